"""What a calibration starts from: the cues, the GPS motion and what is known beforehand."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vid2sim.base.errors import FormatError, ImpossibleValueError
from vid2sim.core.calibration import EgoMotionSample, FlowPair, FrameLines, LaneWidthSample
from vid2sim.core.camera import FOV_RANGE_DEG, MAX_MOUNT_ANGLE_DEG

#: Camera-file keys a partial prior may give, and the physical range of each (the
#: focal length is checked against the image size in :meth:`CameraPrior.check`).
PRIOR_KEYS = ("fx", "fy", "cx", "cy", "k1", "k2", "pitch_deg", "yaw_deg", "roll_deg",
              "height_m")
#: Largest |k1|, |k2| a prior may give (the estimator's own bounds; a lens beyond folds).
MAX_PRIOR_DISTORTION = 0.6


@dataclass(frozen=True, slots=True)
class CameraPrior:
    """A partial camera description (e.g. only the focal length from a phone's spec sheet,
    or only the mount height): the values given are kept, the rest estimated.

    :param values: camera-file keys -> values (``dist`` given as ``k1``, ``k2``), held
    :param path: where it came from (for messages and the camera file's ``source``)
    :param soft: camera-file keys -> (value, one-sigma): a prior the data may move (an
        earlier calibration of the same camera from the per-camera cache); keys ``fx``,
        ``k1``, ``k2``, ``height_m``
    :param soft_source: where the soft prior came from
    """

    values: dict[str, float] = field(default_factory=dict)
    path: str | None = None
    soft: dict[str, tuple[float, float]] = field(default_factory=dict)
    soft_source: str = ""

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None, path: str | Path | None = None) -> CameraPrior:
        """The prior of a YAML mapping (unknown keys ignored, ``dist`` split into k1, k2)."""
        if d is None:
            return cls(path=str(path) if path else None)
        if not isinstance(d, dict):
            raise FormatError(path, "camera prior must be a mapping of keys to values")
        vals: dict[str, float] = {}
        raw = dict(d)
        dist = raw.pop("dist", None)
        if dist is not None:
            if not isinstance(dist, (list, tuple)) or not dist:
                raise FormatError(path, f"dist must be a list of numbers, got {dist!r}")
            raw.setdefault("k1", dist[0])
            raw.setdefault("k2", dist[1] if len(dist) > 1 else 0.0)
        for key in PRIOR_KEYS:
            if key in raw and raw[key] is not None:
                v = raw[key]
                # text that spells a number is one, as in a camera file (PyYAML reads
                # ``1e6``, without a sign in the exponent, as text)
                number = None
                if not isinstance(v, bool) and isinstance(v, (int, float, str)):
                    try:
                        number = float(v)
                    except ValueError:
                        number = None
                if number is None:
                    raise FormatError(path, f"camera prior {key} is not a number: {v!r}")
                vals[key] = number
        return cls(values=vals, path=str(path) if path else None)

    def check(self, width_px: int, height_px: int) -> None:
        """Raise :class:`ImpossibleValueError` for values no camera of this image has."""
        v = self.values
        for key, x in v.items():
            if not math.isfinite(x):
                raise ImpossibleValueError(self.path, f"camera prior {key} is {x}, not finite",
                                           "give a number or leave the key out to estimate it")
        lo, hi = FOV_RANGE_DEG
        for key, side in (("fx", width_px), ("fy", height_px)):
            if key in v:
                if v[key] <= 0:
                    raise ImpossibleValueError(self.path, f"{key} {v[key]:g} must be positive",
                                               "the focal length in pixels")
                fov = math.degrees(2 * math.atan(side / (2 * v[key])))
                if not lo <= fov <= hi:
                    raise ImpossibleValueError(
                        self.path, f"{key} {v[key]:g} px gives a {fov:.1f} deg field of view "
                        f"over {side} px", f"a camera's is {lo:g}-{hi:g} deg")
        if "cx" in v and not 0 <= v["cx"] <= width_px:
            raise ImpossibleValueError(self.path, f"cx {v['cx']:g} lies outside the image",
                                       f"0-{width_px} px; leave it out for the image centre")
        if "cy" in v and not 0 <= v["cy"] <= height_px:
            raise ImpossibleValueError(self.path, f"cy {v['cy']:g} lies outside the image",
                                       f"0-{height_px} px; leave it out for the image centre")
        for key in ("k1", "k2"):
            if key in v and abs(v[key]) > MAX_PRIOR_DISTORTION:
                raise ImpossibleValueError(self.path, f"{key} {v[key]:g} is not a lens's "
                                           f"(|{key}| <= {MAX_PRIOR_DISTORTION:g})")
        for key in ("pitch_deg", "yaw_deg", "roll_deg"):
            if key in v and abs(v[key]) > MAX_MOUNT_ANGLE_DEG:
                raise ImpossibleValueError(self.path, f"{key} {v[key]:g} is not a forward "
                                           "camera's mounting", "the unit is degrees")
        if "height_m" in v and not 0.2 <= v["height_m"] <= 5.0:
            raise ImpossibleValueError(self.path, f"height_m {v['height_m']:g} is not a "
                                       "camera height above a road (0.2-5 m)")


@dataclass(frozen=True, slots=True)
class LaneWidthPrior:
    """The width of the road's lanes: from the map's tags, or a named prior."""

    width_m: float
    std_m: float
    source: str


@dataclass(slots=True)
class CalibrationInput:
    """Everything one calibration sees.

    :param motion: the GPS motion of each flow pair (same order), None without GPS
    :param vehicle_points_masked: flow points dropped inside vehicle boxes before the fit
    :param gps_yaw_usable: the GPS's heading is good enough to weigh a turn's image shift
        against (an INS or a smoothed course; see :class:`~vid2sim.calib.CalibrationConfig`)
    """

    width_px: int
    height_px: int
    pairs: list[FlowPair]
    lines: list[FrameLines]
    prior: CameraPrior = field(default_factory=CameraPrior)
    motion: list[EgoMotionSample] | None = None
    lane_prior: LaneWidthPrior | None = None
    lane_widths: list[LaneWidthSample] = field(default_factory=list)
    gps_label: str = ""
    vehicle_points_masked: int = 0
