"""Records of camera self-calibration: the measured cues and the estimate with its spread.

The detect wings measure pixels (sparse flow of the image below the middle, lane-marking
segments, long straight edges); :mod:`vid2sim.calib` turns these records, with the GPS
motion on the video clock, into a :class:`CameraEstimate`; the application layer writes it
as a camera file and into the scenario. Pixels are raw (distorted) image pixels of the
video's frame size throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from vid2sim.core.camera import Camera

#: The parameters a calibration estimates, in camera-file keys (fx = fy: square pixels).
PARAMETERS = ("fx", "k1", "k2", "pitch_deg", "yaw_deg", "roll_deg", "height_m")


class ParameterSource(str, Enum):
    """Where a camera parameter's value came from (the camera file's ``source``)."""

    #: measured from the video (and GPS): the std says how well
    ESTIMATED = "estimated"
    #: given in the prior camera file and kept
    CAMERA_FILE = "camera file"
    #: not observable in this clip: the named prior's value
    PRIOR = "prior"


@dataclass(frozen=True, slots=True)
class FlowPair:
    """Sparse optical flow between two frames of the lower image (points a -> b).

    :param frame_a, frame_b: 0-based frame indices (a earlier)
    :param t_a_s, t_b_s: their video times [s]
    :param points_a, points_b: (N, 2) raw pixels of the same scene points
    """

    frame_a: int
    frame_b: int
    t_a_s: float
    t_b_s: float
    points_a: np.ndarray
    points_b: np.ndarray

    @property
    def dt_s(self) -> float:
        return self.t_b_s - self.t_a_s


@dataclass(frozen=True, slots=True)
class FrameLines:
    """Line evidence of one frame.

    :param segments: (M, 4) straight segments x1, y1, x2, y2 [raw px] leaning like lane
        markings and road edges (for the road's vanishing point)
    :param chains: long edge chains that are straight up to a lens's bow, each (K, 2) raw
        pixels ordered along the edge (for the plumb-line distortion)
    """

    frame: int
    t_s: float
    segments: np.ndarray
    chains: tuple[np.ndarray, ...] = ()


@dataclass(frozen=True, slots=True)
class LaneWidthSample:
    """The ego lane's width measured with a provisional camera in one frame.

    Lateral offsets on the road scale with the camera height and not with the focal length
    (``y = -h (u - c) / (v - v_h)``), so ``lane_width_m / camera_height_m`` is the lane's
    width in camera heights whatever the provisional height was.
    """

    frame: int
    lane_width_m: float
    camera_height_m: float

    @property
    def width_in_heights(self) -> float:
        return self.lane_width_m / self.camera_height_m


@dataclass(frozen=True, slots=True)
class EgoMotionSample:
    """The ego's motion between a flow pair's frames on the video clock (from GPS).

    :param distance_m: path length between the two frame times [m]
    :param yaw_change_rad: heading change (counter-clockwise positive) [rad]
    """

    frame_a: int
    distance_m: float
    yaw_change_rad: float
    distance_std_m: float
    yaw_std_rad: float


@dataclass(frozen=True, slots=True)
class ParameterEstimate:
    """One camera parameter: value, one-sigma, where it came from, the cue that fixed it."""

    value: float
    std: float
    source: ParameterSource
    cue: str = ""

    def as_dict(self) -> dict:
        return {"value": self.value, "std": self.std if math.isfinite(self.std) else None,
                "source": self.source.value, "cue": self.cue}


@dataclass(slots=True)
class TimeOffset:
    """The GPS clock against the video's: a fix ``u`` seconds after the first is at video
    time ``offset_s + u / rate``.

    :param offset_s: video time of the GPS's first fix [s]
    :param observable: False when the motion was too uniform to tell (``reason`` says why)
    :param rate: GPS seconds per video second (1: the clocks tick alike; KITTI's video.mp4
        plays frames captured every 0.1032 s at 0.1 s: 1.03), 1 where not fitted
    :param rate_std: its one-sigma, 0 where not fitted
    :param rate_fitted: the rate was observable and is used
    """

    offset_s: float
    std_s: float
    observable: bool
    reason: str = ""
    rate: float = 1.0
    rate_std: float = 0.0
    rate_fitted: bool = False


@dataclass(slots=True)
class CameraEstimate:
    """A calibrated camera with the spread and source of each parameter.

    :param camera: the camera (distortion, mounting and height included)
    :param parameters: per :data:`PARAMETERS` key, its :class:`ParameterEstimate`
    :param frames: frames whose pixels were used
    :param notes: what the user must know (``warning:`` lines for unobservable parameters)
    :param speeds: visual ego speed per flow pair (t_s, speed [m/s]) at the estimated
        height, for camera-only clips
    """

    camera: Camera
    parameters: dict[str, ParameterEstimate]
    frames: list[int] = field(default_factory=list)
    notes: list = field(default_factory=list)
    calibrated_from: list[str] = field(default_factory=list)
    speeds: list[tuple[float, float]] = field(default_factory=list)
    time_offset: TimeOffset | None = None
    residual_px: float = float("nan")
    #: visual heading change of each fitted pair [rad], by its first frame (time sync)
    yaw_changes: dict[int, float] = field(default_factory=dict)

    def std(self, name: str) -> float:
        p = self.parameters.get(name)
        return p.std if p is not None else float("nan")

    def summary(self) -> str:
        """One line: each estimated parameter with its one-sigma."""
        units = {"fx": "px", "height_m": "m", "pitch_deg": "deg", "yaw_deg": "deg",
                 "roll_deg": "deg", "k1": "", "k2": ""}
        parts = []
        for key, p in self.parameters.items():
            if p.source is ParameterSource.ESTIMATED:
                parts.append(f"{key} {p.value:.4g} +- {p.std:.2g}{' ' + units[key] if units[key] else ''}")
            elif p.source is ParameterSource.PRIOR and key != "k2":
                parts.append(f"{key} {p.value:.4g} (prior)")
        return ", ".join(parts)
