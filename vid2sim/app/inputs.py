"""The inputs of a run in one record, with the one table of input roles and their checks."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path

from vid2sim.base.errors import ImpossibleValueError, MissingInputError
from vid2sim.base.fileio import sha256_path

#: Every input a run may take: (field of :class:`Inputs` and manifest column, label used in
#: messages and the report). The order is the order of ``source.inputs`` in scenario.json.
INPUT_ROLES: tuple[tuple[str, str], ...] = (
    ("video", "video"), ("gps", "GPS"), ("map", "map"), ("camera", "camera"),
    ("detections", "detections"), ("keyframes", "keyframes"))

#: The numbers that come with the inputs (manifest columns too).
INPUT_NUMBERS: tuple[str, ...] = ("fps", "gps_offset_s", "ego_speed_mps")

#: Options of tracklet keyframes, recorded only when given.
KEYFRAME_OPTIONS: tuple[str, ...] = ("keyframe_calib", "keyframe_rate_hz")

#: Fastest ego speed a user may assume without GPS [m/s] (250 km/h: beyond it the value is
#: a unit mistake, e.g. km/h given as m/s).
MAX_EGO_SPEED_MPS = 70.0
#: Largest frame rate of a folder of images [frames/s] (high-speed cameras stop near 1,000).
MAX_FPS = 1000.0
#: Largest |GPS time offset| [s]: a day; beyond it the clocks are not of the same drive.
MAX_GPS_OFFSET_S = 86_400.0


@dataclass(frozen=True, slots=True)
class Inputs:
    """What one run reads: files and the numbers that say how to read them.

    :param video: video file or folder of images
    :param gps: GPS trace (GPX, NMEA, BDD100K JSON, KITTI OXTS folder, CSV)
    :param map: OpenStreetMap extract (.osm, .osm.pbf)
    :param camera: camera YAML or KITTI calibration file
    :param detections: imported boxes (MOT CSV, Scalabel JSON) used instead of a detector
    :param keyframes: annotated keyframes (Scalabel JSON, KITTI label_02, CVAT XML)
    :param fps: frame rate of an image folder [frames/s] (videos carry their own)
    :param gps_offset_s: video time of the first GPS fix [s]: the GPS time base of every stage
        (trajectory and map matching alike); None = the file's own clock
    :param ego_speed_mps: the ego's assumed constant speed without GPS [m/s]
    :param keyframe_calib: KITTI tracklet keyframes only: the folder of the drive's
        ``calib_velo_to_cam.txt`` and ``calib_cam_to_cam.txt`` (default: the XML's folder)
    :param keyframe_rate_hz: KITTI tracklet keyframes only: keyframes a second (default:
        every frame)
    """

    video: Path | None = None
    gps: Path | None = None
    map: Path | None = None
    camera: Path | None = None
    detections: Path | None = None
    keyframes: Path | None = None
    fps: float | None = None
    gps_offset_s: float | None = None
    ego_speed_mps: float = 0.0
    keyframe_calib: Path | None = None
    keyframe_rate_hz: float | None = None

    def paths(self) -> dict[str, Path]:
        """Role -> path of the inputs given, in :data:`INPUT_ROLES` order."""
        return {role: Path(getattr(self, role)) for role, _ in INPUT_ROLES
                if getattr(self, role) is not None}

    def labelled_paths(self) -> dict[str, str]:
        """Label -> path as text, for the report's "this run" table."""
        labels = dict(INPUT_ROLES)
        return {labels[role]: str(p) for role, p in self.paths().items()}

    def check(self) -> None:
        """Raise :class:`InputError` for a missing file or an impossible number.

        Run before any long work, so that a typo fails in a second, not a minute.
        """
        labels = dict(INPUT_ROLES)
        for role, p in self.paths().items():
            if not p.exists():
                raise MissingInputError(
                    p, "no such file", f"check the path of the {labels[role]} input")
        for name in INPUT_NUMBERS:
            value = getattr(self, name)
            if value is not None and not math.isfinite(value):
                raise ImpossibleValueError(None, f"{name} must be a finite number, got {value}")
        if self.fps is not None and not 0 < self.fps <= MAX_FPS:
            raise ImpossibleValueError(
                None, f"fps must be in (0, {MAX_FPS:g}] frames/s, got {self.fps:g}")
        if not 0 <= self.ego_speed_mps <= MAX_EGO_SPEED_MPS:
            raise ImpossibleValueError(None, f"ego speed must be 0-{MAX_EGO_SPEED_MPS:g} m/s, got "
                                       f"{self.ego_speed_mps:g}", "the unit is m/s")
        if self.keyframe_calib is not None and not Path(self.keyframe_calib).is_dir():
            raise MissingInputError(self.keyframe_calib, "no such folder",
                                    "the folder of calib_velo_to_cam.txt and calib_cam_to_cam.txt")
        if self.keyframe_rate_hz is not None and not (
                math.isfinite(self.keyframe_rate_hz) and self.keyframe_rate_hz > 0):
            raise ImpossibleValueError(None, f"keyframe rate must be a positive number of "
                                       f"keyframes a second, got {self.keyframe_rate_hz:g}")
        if self.gps_offset_s is not None and abs(self.gps_offset_s) > MAX_GPS_OFFSET_S:
            raise ImpossibleValueError(
                None, f"GPS offset {self.gps_offset_s:g} s is more than a day",
                "give the video time of the first fix in seconds")

    def fingerprints(self) -> list[dict[str, str]]:
        """``source.inputs`` of a scenario: role, file name and sha256 of each input.

        Names, not paths: the same inputs reached from another folder give the same record.
        """
        return [{"role": role, "name": p.name, "sha256": sha256_path(p)}
                for role, p in self.paths().items()]

    def recorded(self) -> dict:
        """The inputs' numbers and file names as recorded in ``source.options``."""
        out: dict = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "video" or (f.name in KEYFRAME_OPTIONS and value is None):
                continue
            out[f.name] = Path(value).name if isinstance(value, Path) else value
        return out
