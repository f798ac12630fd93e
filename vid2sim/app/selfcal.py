"""The camera of a run: a camera file, or a self-calibration, and ``vid2sim calibrate``.

Every video command (``track``, ``build``, ``batch``) without a whole ``--camera`` file
calibrates the camera on the clip (:mod:`vid2sim.app.calibrate`), prints the estimate with
its one-sigma, and writes it where the command writes (``camera.yaml`` in a build folder,
``camera`` in ``scenario.json``). Where the scale cannot be observed (no GPS motion, no
lanes) a ``warning:`` names the prior used. An earlier calibration of the same camera
(frame size, rate, codec) from the per-camera cache is the prior of a clip that cannot
observe its own scale.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from vid2sim.app import calibrate as cal
from vid2sim.app.camerafile import (
    cached_prior,
    camera_key,
    read_camera_or_prior,
    store_in_cache,
    write_camera_file,
)
from vid2sim.app.inputs import Inputs
from vid2sim.app.loaders import load_trace, load_video_info
from vid2sim.app.settings import Settings
from vid2sim.base.errors import MissingInputError
from vid2sim.base.fileio import check_output_file
from vid2sim.calib import CameraPrior, LaneWidthPrior
from vid2sim.calib.sync import on_video_clock
from vid2sim.core.calibration import CameraEstimate, TimeOffset
from vid2sim.core.camera import Camera, fit_camera_to_frames
from vid2sim.core.records import EgoTrack, GpsTrace, Note, VideoInfo
from vid2sim.geo.trace import smooth_ego, video_t0_utc


@dataclass(slots=True)
class CameraChoice:
    """The camera a run uses and how it was found.

    :param camera: a whole camera file's camera, or None until calibrated
    :param prior: what a partial camera file (or the cache) said, when calibrating
    :param cues: the measured cues, when calibrating
    :param estimate: the self-calibration, once made
    :param offset: the GPS clock's estimated offset, when synced
    :param vehicles: the vehicle boxes of a frame (the run's detector or imported boxes),
        whose points the road's flow drops; None: no mask (``vid2sim calibrate``)
    """

    camera: Camera | None
    notes: list[Note] = field(default_factory=list)
    prior: CameraPrior | None = None
    cues: cal.Cues | None = None
    estimate: CameraEstimate | None = None
    offset: TimeOffset | None = None
    cache_key: str | None = None
    vehicles: cal.VehicleBoxes | None = None

    @property
    def calibrating(self) -> bool:
        return self.camera is None


def start_camera(inputs: Inputs, info: VideoInfo, settings: Settings) -> CameraChoice:
    """A whole camera file fitted to the frames; else a prior (partial file or cache) to
    calibrate from, checked against the video's size before any long work."""
    if inputs.camera is not None:
        read = read_camera_or_prior(Path(inputs.camera))
        if isinstance(read, Camera):
            cam, note = fit_camera_to_frames(read, info.width, info.height, inputs.camera)
            return CameraChoice(camera=cam, notes=[Note.warning(note)] if note else [])
        read.check(info.width, info.height)
        return CameraChoice(camera=None, prior=read)
    key = camera_key(Path(inputs.video), info.width, info.height, info.fps)
    prior = cached_prior(key) if settings.camera_cache else None
    return CameraChoice(camera=None, prior=prior or CameraPrior(), cache_key=key)


def measure_cues_for(choice: CameraChoice, inputs: Inputs, info: VideoInfo,
                     settings: Settings) -> None:
    """Measure the clip's cues (once)."""
    if choice.cues is None:
        choice.cues = cal.measure_cues(Path(inputs.video), info, inputs.fps,
                                       cal.calibration_config(settings), choice.vehicles)


def visual_ego_speeds(choice: CameraChoice, info: VideoInfo, settings: Settings
                      ) -> list[tuple[float, float]]:
    """The ego's speed per flow pair from the road's flow at the camera's height (the
    self-calibration's, or with a camera file's camera held)."""
    if choice.estimate is not None:
        return choice.estimate.speeds
    if choice.cues is None or choice.camera is None:
        return []
    if cal.check_cues(choice.cues, Path(".")) is not None:
        return []
    est = cal.fit_cues(replace(choice.cues, held={}), info, _prior_of(choice.camera),
                       cal.calibration_config(settings))
    return est.speeds


def needs_sync(inputs: Inputs, trace: GpsTrace | None) -> bool:
    """The GPS has no clock against the video: neither ``--gps-offset`` nor the file's."""
    return trace is not None and inputs.gps_offset_s is None and trace.video_start_utc_s is None


def sync_offset(choice: CameraChoice, inputs: Inputs, info: VideoInfo, settings: Settings,
                trace: GpsTrace) -> tuple[Inputs, GpsTrace]:
    """Estimate the GPS offset (and clock rate) from the motion profiles; the inputs with
    the offset and the trace re-timed by the rate (:func:`vid2sim.calib.sync.on_video_clock`)
    if observable, else both as given.

    Measures the cues first if a camera file made that unnecessary so far."""
    cfg = cal.calibration_config(settings)
    cues = choice.cues or cal.measure_cues(Path(inputs.video), info, inputs.fps, cfg,
                                           for_sync=True)
    if cal.check_cues(cues, Path(inputs.video)) is not None:
        choice.notes.append(Note.warning("GPS-video time offset not estimated: the clip "
                                         "shows too little road motion"))
        return inputs, trace
    ego0, _ = smooth_ego(trace, rate_hz=settings.rate_hz, gps_offset_s=0.0,
                         params=settings.trace)
    prior = choice.prior if choice.prior is not None else _prior_of(choice.camera)
    off = cal.sync_clock(cues, info, prior, trace, ego0, cfg, settings.sync)
    choice.offset = off
    if off.observable:
        rate = (f"; the GPS clock runs at {off.rate:.3f} +- {off.rate_std:.3f} s per video "
                "second, its fixes re-timed onto the video clock") if off.rate_fitted else ""
        choice.notes.append(Note.estimate(
            f"GPS-video time offset {off.offset_s:+.2f} +- {off.std_s:.2f} s from the motion "
            f"profiles ({off.reason}): the first fix at video time {off.offset_s:+.2f} s"
            + rate))
        return (replace(inputs, gps_offset_s=float(off.offset_s)),
                on_video_clock(trace, off.rate) if off.rate_fitted else trace)
    choice.notes.append(Note.warning(
        f"GPS-video time offset not observable: {off.reason}; the first fix is taken as the "
        "first frame (pass --gps-offset)"))
    return inputs, trace


def _prior_of(camera: Camera | None) -> CameraPrior:
    """A whole camera as a held prior (the sync's visual profiles then need no scale)."""
    if camera is None:
        return CameraPrior()
    return CameraPrior(values={"fx": camera.fx, "cx": camera.cx, "cy": camera.cy,
                               "k1": camera.dist[0], "k2": camera.dist[1] if len(camera.dist)
                               > 1 else 0.0, "height_m": camera.height_m})


def finish_camera(choice: CameraChoice, inputs: Inputs, info: VideoInfo, settings: Settings,
                  trace: GpsTrace | None = None, ego: EgoTrack | None = None,
                  lane_prior: LaneWidthPrior | None = None) -> Camera:
    """The run's camera: the file's, or the self-calibration (its notes added)."""
    if not choice.calibrating:
        return choice.camera
    cfg = cal.calibration_config(settings)
    prior = choice.prior or CameraPrior()
    why = cal.check_cues(choice.cues, Path(inputs.video))
    if why is not None:
        cam, notes = cal.default_prior_camera(info, prior, cfg, why)
        choice.camera, choice.notes = cam, choice.notes + notes
        return cam
    motion = None
    duration = info.n_frames / info.fps if info.fps else 0.0
    if ego is not None:
        if cal.gps_moves(ego, duration):
            yaw_std = cal.yaw_rate_std_for(trace, cfg)
            t0, _ = video_t0_utc(trace, inputs.gps_offset_s)
            motion = cal.motion_from_series(cal.gps_series(trace, t0, ego), choice.cues.pairs,
                                            cfg, yaw_std)
        else:
            choice.notes.append(Note.warning(
                "the GPS never moves during the clip: not used for the camera's scale"))
    label = f"{trace.format} {Path(inputs.gps).name}" if trace is not None and inputs.gps \
        else ""
    est = cal.fit_cues(choice.cues, info, prior, cfg, motion, lane_prior or
                       cal.lane_prior_from_roads([], None, cfg), label)
    est.time_offset = choice.offset
    if prior.soft_source:
        est.notes.append(Note.estimate(f"camera prior from {prior.soft_source}"))
    choice.estimate, choice.camera = est, est.camera
    choice.notes += est.notes
    if settings.camera_cache and choice.cache_key is not None:
        store_in_cache(est, choice.cache_key)
    return est.camera


def camera_line(choice: CameraChoice) -> str:
    """The summary line of the camera used."""
    if choice.estimate is None:
        return "camera: " + ("file" if choice.prior is None else "prior (not calibrated)")
    return "camera estimated: " + choice.estimate.summary()


# --------------------------------------------------------------------------- the command


def run_calibrate(inputs: Inputs, out_path: Path, settings: Settings | None = None,
                  vehicles: cal.VehicleBoxes | None = None) -> str:
    """``vid2sim calibrate``: self-calibrate the camera of a clip and write its camera file
    (``vehicles``: a frame's vehicle boxes, whose points the road's flow drops; the command
    itself loads no detector).

    Raises
    ------
    ImpossibleValueError, FormatError
        A prior with impossible values, or one that is not a camera file.
    MissingInputError
        A video too dark or too short to calibrate (nothing is written).
    OutputError
        An unwritable output.
    """
    settings = settings or Settings()
    settings.check()
    inputs.check()
    video = cal.require_video(inputs)
    info = load_video_info(inputs)
    start = time.perf_counter()
    choice = start_camera(replace(inputs, camera=inputs.camera), info, settings)
    if not choice.calibrating:  # a whole camera file: calibrate with it as a prior
        choice = CameraChoice(camera=None, prior=_prior_of(choice.camera))
    choice.vehicles = vehicles
    check_output_file(out_path)
    measure_cues_for(choice, inputs, info, settings)
    why = cal.check_cues(choice.cues, video)
    if why is not None:
        raise MissingInputError(video, why,
                                "calibrate on a longer clip of driving in daylight")
    trace = ego = None
    if inputs.gps is not None:
        trace = load_trace(inputs)
        if needs_sync(inputs, trace):
            inputs, trace = sync_offset(choice, inputs, info, settings, trace)
        ego, _ = smooth_ego(trace, rate_hz=settings.rate_hz, gps_offset_s=inputs.gps_offset_s,
                            params=settings.trace)
    finish_camera(choice, inputs, info, settings, trace, ego)
    write_camera_file(choice.estimate, Path(out_path), Path(video).name)
    lines = [(f"{video}: {info.width}x{info.height}, {len(choice.cues.pairs)} frame pairs and "
              f"{len(choice.cues.lines)} frames measured in {time.perf_counter() - start:.1f} s"),
             camera_line(choice)]
    lines += [f"{n.kind.value}: {n}" for n in choice.notes]
    lines.append(f"camera file -> {out_path}")
    return "\n".join(lines)
