"""Camera files of self-calibration: a prior read, an estimate written, the per-camera cache.

The written file is the camera YAML every command reads (:func:`vid2sim.core.camera.
load_camera`) with, beside the usual keys, ``std`` and ``source`` per estimated parameter,
``calibrated_from`` (the cues), ``frames`` (the video frames whose pixels were used) and
``video``. A file lacking some of the usual keys is a *prior*: its values are held and the
rest estimated.
"""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path

import cv2
import yaml

from vid2sim.base.errors import FormatError, InputError
from vid2sim.base.fileio import read_input_text, write_text_atomic
from vid2sim.calib import CameraPrior
from vid2sim.core.calibration import CameraEstimate, ParameterSource
from vid2sim.core.camera import MAX_CAMERA_FILE_BYTES, Camera, load_camera

#: Keys a camera file must have to be a whole camera (else it is a prior).
WHOLE_CAMERA_KEYS = ("image_width", "image_height", "fx", "fy", "cx", "cy")


def read_camera_or_prior(path: Path) -> Camera | CameraPrior:
    """A whole camera file as a :class:`Camera`, a partial one as a :class:`CameraPrior`.

    Raises
    ------
    InputError
        Unreadable YAML, a value that is not a number, or an impossible value (a whole
        camera's checks; a prior's are made against the video's size later).
    """
    text = read_input_text(path, max_bytes=MAX_CAMERA_FILE_BYTES)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError:
        data = None  # a KITTI calibration file, or broken YAML: load_camera says which
    if isinstance(data, dict) and not all(k in data for k in WHOLE_CAMERA_KEYS):
        return CameraPrior.from_dict(data, path)
    return load_camera(path)


def _number(value: float) -> float | None:
    return round(float(value), 6) if math.isfinite(value) else None


def camera_record(estimate: CameraEstimate, video: str | None = None,
                  scenario: bool = False) -> dict:
    """The camera-file mapping of an estimate: ``source`` and ``std`` per parameter. For
    ``scenario.json``'s ``camera`` (``scenario``): ``source`` is ``"estimated"`` and the
    per-parameter sources are ``parameter_sources``."""
    cam = estimate.camera
    rec = {k: (_number(v) if isinstance(v, float) else v) for k, v in cam.to_dict().items()}
    rec["dist"] = [_number(v) for v in cam.dist]
    rec["std"] = {k: _number(p.std) for k, p in estimate.parameters.items()
                  if p.source is not ParameterSource.CAMERA_FILE}
    sources = {k: p.source.value + (f" ({p.cue})" if p.cue and p.source is
                                    ParameterSource.ESTIMATED else "")
               for k, p in estimate.parameters.items()}
    if scenario:
        rec["source"] = "estimated"
        rec["parameter_sources"] = sources
    else:
        rec["source"] = sources
    rec["calibrated_from"] = list(estimate.calibrated_from)
    rec["frames"] = [int(f) for f in estimate.frames]
    if video:
        rec["video"] = video
    if estimate.time_offset is not None:
        t = estimate.time_offset
        rec["gps_offset_s"] = {"value": _number(t.offset_s), "std": _number(t.std_s),
                               "observable": bool(t.observable)}
        rec["gps_clock_rate"] = {"value": _number(t.rate), "std": _number(t.rate_std),
                                 "fitted": bool(t.rate_fitted)}
    return rec


def camera_yaml(estimate: CameraEstimate, video: str | None = None) -> str:
    """The camera file's text."""
    head = ("# vid2sim camera self-calibration: the camera file format of --camera, with the\n"
            "# one-sigma (std) and source of each parameter and the cues and frames used.\n")
    return head + yaml.safe_dump(camera_record(estimate, video), sort_keys=False)


def write_camera_file(estimate: CameraEstimate, path: Path, video: str | None = None) -> None:
    """Write the estimate's camera file atomically (nothing half-written on a failure)."""
    write_text_atomic(path, camera_yaml(estimate, video))


# --------------------------------------------------------------------------- cache


def default_camera_cache_dir() -> Path:
    """``$VID2SIM_CACHE_DIR/cameras``, else the user cache (as the map cache)."""
    root = os.environ.get("VID2SIM_CACHE_DIR")
    if root:
        return Path(root) / "cameras"
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "vid2sim" / "cameras"


def camera_key(video: Path, width: int, height: int, fps: float) -> str:
    """What identifies a camera in the cache: frame size, rate and the container's codec
    (a dash-cam writes every clip alike; another camera rarely matches all of them)."""
    fourcc = ""
    if not Path(video).is_dir():
        cap = cv2.VideoCapture(str(video))
        code = int(cap.get(cv2.CAP_PROP_FOURCC)) if cap.isOpened() else 0
        cap.release()
        fourcc = "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4)).strip("\x00 ")
    text = f"{width}x{height}@{fps:.3f}:{fourcc}"
    return f"{width}x{height}-" + hashlib.sha256(text.encode()).hexdigest()[:12]


def cached_prior(key: str, cache_dir: Path | None = None) -> CameraPrior | None:
    """A soft prior from an earlier calibration of this camera, if cached and readable."""
    path = (cache_dir or default_camera_cache_dir()) / f"{key}.yaml"
    if not path.is_file():
        return None
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
        std = data.get("std", {})
        soft = {"fx": (float(data["fx"]), float(std["fx"])),
                "height_m": (float(data["height_m"]), float(std["height_m"])),
                "k1": (float(data["dist"][0]), float(std["k1"]))}
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError, IndexError):
        return None
    soft = {k: v for k, v in soft.items() if all(math.isfinite(x) for x in v) and v[1] > 0}
    return CameraPrior(soft=soft, soft_source=f"camera cache {path}") if soft else None


def store_in_cache(estimate: CameraEstimate, key: str, cache_dir: Path | None = None) -> None:
    """Keep an estimate whose scale was observed (focal length and height from the clip)
    as the prior of this camera's next clips; a cache that cannot be written is skipped."""
    scale = [estimate.parameters[k].source is ParameterSource.ESTIMATED
             for k in ("fx", "height_m")]
    if not all(scale):
        return
    folder = cache_dir or default_camera_cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        write_camera_file(estimate, folder / f"{key}.yaml")
    except (OSError, InputError):
        pass


def check_prior_file(prior: CameraPrior, width: int, height: int) -> None:
    """A prior's values against the video's size (raises ``ImpossibleValueError``)."""
    if prior.values and not isinstance(prior.values, dict):
        raise FormatError(prior.path, "camera prior must be a mapping")
    prior.check(width, height)
