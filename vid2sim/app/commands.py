"""The single-stage commands ``export`` and ``eval``: slices of ``build`` (``trace`` and
``road`` are in :mod:`vid2sim.app.gpsroad`, which loads only the GPS and map stack; ``detect``
and ``track`` in :mod:`vid2sim.app.tracking`, which loads only the detection stack).

Each takes the run's :class:`~vid2sim.app.inputs.Inputs` and
:class:`~vid2sim.app.settings.Settings` (or the scenario it works on), loads what it needs
through :mod:`vid2sim.app.loaders` (the same loaders ``build`` uses), checks that its output
can be written before any work, runs the stage functions and writes its output atomically: a
file renamed into place, or a folder staged and moved into place
(:func:`vid2sim.base.fileio.staged_folder`). Each returns the summary text the CLI prints.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vid2sim.app.loaders import load_keyframes_for
from vid2sim.base.errors import FormatError
from vid2sim.base.fileio import (
    check_output_folder,
    staged_folder,
    write_bytes_atomic,
    write_text_atomic,
)
from vid2sim.core import scenario as scenario_io
from vid2sim.core.videofile import video_info
from vid2sim.evaluate.replay import run_eval
from vid2sim.export import FORMATS, replay_script
from vid2sim.export.commonroad import (
    IDS_NAME,
    XML_NAME,
    CommonRoadConfig,
    check_expressible,
    require_commonroad,
    write_commonroad,
)
from vid2sim.export.openscenario import write_openscenario

# --------------------------------------------------------------------------- export, eval

#: The files each export format writes into its folder.
EXPORT_OUTPUTS: dict[str, tuple[str, ...]] = {
    "openscenario": ("scenario.xosc", "road.xodr"),
    "highway-env": ("scenario.json", "replay.py", "preview.png"),
    "commonroad": (XML_NAME, IDS_NAME),
}
#: What ``vid2sim eval`` writes into its folder (a rerun replaces all of it).
EVAL_OUTPUTS: tuple[str, ...] = ("metrics.json", "keyframes", "report.html")


def run_export(scenario_path: Path, fmt: str, out_dir: Path, *, ego_as_obstacle: bool = False,
               commonroad: CommonRoadConfig | None = None) -> str:
    """``vid2sim export``: a scenario.json for a simulator; returns the summary.

    ``openscenario``: ``out_dir/scenario.xosc`` + ``out_dir/road.xodr``.
    ``highway-env``: ``out_dir/scenario.json`` (canonical copy), ``out_dir/replay.py`` (runnable
    example: ACC + AEB ego, or ``--log``) and ``out_dir/preview.png`` (top view of the replay
    with the logged ego at mid-scenario).
    ``commonroad``: ``out_dir/scenario.xml`` (CommonRoad 2020a, commonroad-io's writer; the ego
    also a dynamic obstacle with ``ego_as_obstacle``) + ``out_dir/ids.json`` (vid2sim ids ->
    CommonRoad ids).

    The scenario is validated first (schema, finite numbers, limits, road geometry), the
    outputs are staged and moved into ``out_dir`` together: a failure leaves the folder as it
    was.
    """
    if fmt not in EXPORT_OUTPUTS:
        raise FormatError(
            None, f"unknown export format {fmt!r}", f"use one of {', '.join(FORMATS)}")
    scenario_path = Path(scenario_path)
    if fmt == "commonroad":
        require_commonroad()
    sc = scenario_io.load(scenario_path)
    out_dir = Path(out_dir)
    if fmt == "commonroad":
        check_expressible(sc, scenario_path)
    with staged_folder(out_dir, EXPORT_OUTPUTS[fmt]) as staging:
        if fmt == "openscenario":
            write_openscenario(sc, staging)
            return (f"wrote {out_dir / 'scenario.xosc'} (OpenSCENARIO 1.2, {1 + len(sc.actors)} "
                    f"vehicles, {sc.duration_s:.1f} s) and {out_dir / 'road.xodr'} (OpenDRIVE "
                    f"1.8, {max(len(sc.roads), 1)} road(s))")
        if fmt == "commonroad":
            done = write_commonroad(sc, staging, commonroad, ego_as_obstacle, scenario_path)
            lanelets = sum(len(v) for v in done.ids["lanelets"].values())
            return (f"wrote {out_dir / XML_NAME} (CommonRoad 2020a, {lanelets} lanelets, "
                    f"{len(sc.actors) + ego_as_obstacle} dynamic obstacles, {done.grid.steps} "
                    f"steps of {done.grid.dt_s:g} s, 1 planning problem) and "
                    f"{out_dir / IDS_NAME}")
        scenario_io.save(sc, staging / "scenario.json")
        v_ref = max(float(np.max(sc.ego.trajectory.speed)), 5.0)
        write_text_atomic(staging / "replay.py", replay_script(scenario_path.name, v_ref))
        write_bytes_atomic(staging / "preview.png", _highway_preview_png(sc))
    return (f"wrote {out_dir / 'scenario.json'}, {out_dir / 'replay.py'} and "
            f"{out_dir / 'preview.png'} ({1 + len(sc.actors)} vehicles, {sc.duration_s:.1f} s; "
            f"run: python {out_dir / 'replay.py'})")


def _highway_preview_png(sc) -> bytes:
    """Top view of the highway-env replay with the logged ego at mid-scenario, as PNG."""
    import cv2

    # highway-env and pygame take a second to import: only the highway-env export needs them.
    from vid2sim.export.highway import ReplayEnv

    env = ReplayEnv(sc, ego_mode="log", render_mode="rgb_array",
                    config={"screen_width": 800, "screen_height": 400})
    try:
        env.reset(seed=0)
        action = np.zeros(1, dtype=np.float32)
        for _ in range(env.n_steps // 2):
            env.step(action)
        frame = env.render()
    finally:
        env.close()
    ok, png = cv2.imencode(".png", cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    if not ok:  # pragma: no cover - PNG encoding of an RGB array does not fail
        raise RuntimeError("PNG encoding failed")
    return png.tobytes()


def run_eval_command(scenario_path: Path, keyframes_path: Path, out_dir: Path, *,
                     video: Path | None = None, fps: float | None = None,
                     use_env: bool = True, keyframe_calib: Path | None = None,
                     keyframe_rate_hz: float | None = None) -> str:
    """``vid2sim eval``: replay a scenario at annotated keyframes, score it, write
    ``metrics.json``, ``keyframes/`` and ``report.html`` into ``out_dir`` (staged); the summary.

    With a video, keyframes beyond its frames are an input error before any replay.
    ``keyframe_calib`` / ``keyframe_rate_hz``: for KITTI tracklet keyframes, the drive's
    calibration folder and the keyframes a second.
    """
    out_dir = Path(out_dir)
    check_output_folder(out_dir)
    scenario_io.load(scenario_path)  # the scenario's own errors before the keyframes'
    if video is not None:
        info = video_info(Path(video), fps=fps)
        load_keyframes_for(Path(keyframes_path), Path(video), info, fps, keyframe_calib,
                           keyframe_rate_hz)
    with staged_folder(out_dir, EVAL_OUTPUTS) as staging:
        _, summary = run_eval(scenario_path, keyframes_path, video=video, out_dir=staging,
                              fps=fps, use_env=use_env, scenario_label=str(scenario_path),
                              keyframe_calib=keyframe_calib,
                              keyframe_rate_hz=keyframe_rate_hz)
    return summary.replace(str(staging), str(out_dir))
