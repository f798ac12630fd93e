"""The replay video of a build: projection with known answers, a real render of a short
generated build (decoded back), its report in headless Chromium, and bad input."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys

import cv2
import numpy as np
import pytest

from tests.conftest import REPO
from tests.test_cli_bad_inputs import _assert_one_error_line, _snapshot, read_only
from tests.videoframes import decoded_frames
from vid2sim.base.errors import (
    ImpossibleValueError,
    InconsistentInputError,
    MissingInputError,
    OutputError,
)
from vid2sim.cli.main import main
from vid2sim.core.camera import Camera
from vid2sim.core.outline import CLASS_SHAPES
from vid2sim.core.records import RangedBox
from vid2sim.evaluate.overlay import OverlayConfig, draw_camera, iou_colour, scenario_in_camera
from vid2sim.evaluate.projection import project_box_clipped
from vid2sim.evaluate.replayvideo import layout_for
from vid2sim.evaluate.videoout import best_codec
from vid2sim.samples.drives import helsinki_pbf
from vid2sim.samples.scenarios import parallel_traffic_scenario

# --------------------------------------------------------------------------- projection


def _detection(box, track_id: int = 7) -> RangedBox:
    return RangedBox(frame=0, t_s=0.0, track_id=track_id, category="car", score=0.9,
                     x1=box[0], y1=box[1], x2=box[2], y2=box[3], range_m=17.85, lateral_m=0.0,
                     range_rate_mps=-2.0, range_std_m=0.5, is_lead=True, lane=0)


def _known_actor():
    """Actor 7 straight ahead: centre 20 m ahead, 4.3 x 1.8 x 1.5 m, camera 1.65 m high,
    level, on the vehicle-frame origin."""
    sc = parallel_traffic_scenario(actors=[("7", 20.0, 0.0, 8.0, 0.0, 4.0)])
    cam = Camera.from_dict(sc.camera)
    e = sc.ego.trajectory.state_at(0.0)
    a = sc.actors[0].trajectory.state_at(0.0)
    ego = (float(e["x"]), float(e["y"]), float(e["heading"]))
    return sc, cam, ego, {"7": (float(a["x"]), float(a["y"]), float(a["heading"]))}


def test_the_projection_of_a_known_actor_lands_on_its_box():
    sc, cam, ego, actors = _known_actor()
    rear, front = 20.0 - 2.15, 20.0 + 2.15
    # the pinhole by hand: the rear face's bottom corners give the sides and the bottom, the
    # front top corners (0.15 m below the camera, farthest) the top
    expected = (cam.cx - cam.fx * 0.9 / rear, cam.cy + cam.fy * 0.15 / front,
                cam.cx + cam.fx * 0.9 / rear, cam.cy + cam.fy * 1.65 / rear)
    sims = scenario_in_camera(sc, cam, ego, actors, [_detection(expected)], outlines=None)
    assert len(sims) == 1
    sim = sims[0]
    np.testing.assert_allclose(sim.box.box_px, expected, atol=1e-6)
    hull = sim.hull_px
    np.testing.assert_allclose([*hull.min(axis=0), *hull.max(axis=0)], expected, atol=1e-3)
    assert sim.iou == pytest.approx(1.0)
    assert iou_colour(sim.iou, OverlayConfig()) == iou_colour(0.7, OverlayConfig())


def test_outline_hull_spans_the_evaluation_s_box_and_iou_judges_a_shifted_detection():
    sc, cam, ego, actors = _known_actor()
    view = project_box_clipped(cam, np.array([20.0, 0.0, 0.0]), 4.3, 1.8, 1.5, 0.0,
                               outline=CLASS_SHAPES["car"])
    sims = scenario_in_camera(sc, cam, ego, actors, [_detection(view.box_px)])
    hull = sims[0].hull_px
    np.testing.assert_allclose([*hull.min(axis=0), *hull.max(axis=0)], view.box_px, atol=1e-3)
    x1, y1, x2, y2 = view.box_px
    shifted = (x1 + (x2 - x1) * 0.6, y1, x2 + (x2 - x1) * 0.6, y2)  # IoU 0.4 / 1.6 = 0.25
    sims = scenario_in_camera(sc, cam, ego, actors, [_detection(shifted)])
    assert sims[0].iou == pytest.approx(0.25, abs=1e-6)
    cfg = OverlayConfig()
    assert iou_colour(sims[0].iou, cfg) not in (iou_colour(0.9, cfg), iou_colour(0.6, cfg))
    # no detection of track 7 in the frame: the "undetected" colour
    none = scenario_in_camera(sc, cam, ego, actors, [_detection(shifted, track_id=8)])
    assert none[0].iou is None
    img = draw_camera(np.zeros((cam.image_height, cam.image_width, 3), np.uint8), [], sims)
    u, v = np.round(hull[np.argmax(hull[:, 1])]).astype(int)  # the hull's lowest point
    patch = img[v - 2:v + 3, u - 2:u + 3].reshape(-1, 3)
    assert (np.abs(patch.astype(int) - iou_colour(sims[0].iou, cfg)).sum(axis=1) < 60).any()


# --------------------------------------------------------------------------- a short build


_frames = decoded_frames


@pytest.fixture(scope="module")
def short_build(tmp_path_factory):
    """A generated 3 s clip (30 frames, 480x270) with GPS, map, camera, imported boxes and
    keyframes, built with --render (a few seconds)."""
    from vid2sim.samples.demo_sample import generate_demo_sample

    root = tmp_path_factory.mktemp("short")
    sample = generate_demo_sample(root / "clip", duration_s=3.0, width=480, height=270)
    out = root / "B"
    code = main(["-q", "build", str(sample.video), "--gps", str(sample.gps), "--map",
                 str(helsinki_pbf()), "--camera", str(sample.camera), "--detections",
                 str(sample.detections), "--keyframes", str(sample.keyframes), "--offline",
                 "--render", "--out", str(out)])
    assert code == 0
    return sample, out


def test_build_render_writes_a_replay_of_every_frame(short_build):
    sample, out = short_build
    frames = _frames(out / "replay.mp4")
    width, height = layout_for(480, 270).size
    assert len(frames) == sample.n_frames == 30
    assert frames[0].shape == (height, width, 3) and width >= 1.5 * 480
    # the bird's-eye half changes as the scene moves (the road turns past the ego)
    bev = slice(480 + 4, width)
    assert np.abs(frames[0][:, bev].astype(int) - frames[-1][:, bev].astype(int)).mean() > 2.0
    # the camera half is the video's frame under the drawings
    video = _frames(sample.video)
    diff = np.abs(frames[15][40:260, :480].astype(int) - video[15][40:260].astype(int))
    assert np.median(diff) < 12
    text = (out / "report.html").read_text()
    assert re.search(r"<video controls[^>]* src='replay\.mp4'", text)
    assert "replay.mp4#t=0.50" in text  # the first keyframe, linked to its time


def test_render_a_span_at_another_rate_replaces_the_report_s_video(short_build, tmp_path):
    sample, built = short_build
    out = tmp_path / "B"
    shutil.copytree(built, out)
    code = main(["-q", "render", str(out), "--video", str(sample.video), "--from", "0.5",
                 "--to", "2.0", "--fps", "5", "--out", str(out / "part.mp4")])
    assert code == 0
    assert len(_frames(out / "part.mp4")) == 8  # 0.5, 0.7, ..., 1.9 s
    text = (out / "report.html").read_text()
    assert "src='part.mp4'" in text and "src='replay.mp4'" not in text
    assert text.count("<video") == 1
    # without the video: a grey canvas under the boxes, one frame per recorded frame
    code = main(["-q", "render", str(out), "--out", str(tmp_path / "grey.mp4")])
    assert code == 0
    grey = _frames(tmp_path / "grey.mp4")
    assert len(grey) == 30  # the build's video as recorded: 30 frames at 10 frames/s
    assert abs(float(np.median(grey[5][:270, :480])) - 90) < 6


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        if shutil.which(name):
            return shutil.which(name)
    return None


@pytest.mark.skipif(_chromium() is None, reason="no chromium binary on PATH "
                    "(apt-get install chromium)")
@pytest.mark.skipif(best_codec() != "h264", reason="PyAV's FFmpeg has no libx264: "
                    "browsers do not play MPEG-4 part 2")
def test_the_report_s_video_plays_in_headless_chromium(short_build, tmp_path):
    _, out = short_build
    # The report has no scripts; a copy beside it with one added plays its <video> element
    # (muted, as autoplay rules want) and writes what it saw into the page's title.
    probe = out / "probe.html"
    probe.write_text((out / "report.html").read_text().replace("</body>", """<script>
const v = document.querySelector('video'); v.muted = true;
v.addEventListener('error', () => { document.title = 'error ' + (v.error && v.error.code); });
v.play().then(() => setTimeout(() => { document.title = 'played ' + v.currentTime.toFixed(2)
  + ' ' + v.videoWidth + 'x' + v.videoHeight; window.scrollTo(0, v.offsetTop); }, 1500))
 .catch(e => { document.title = 'rejected ' + e.name; });
</script></body>"""))
    base = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--mute-audio",
            "--autoplay-policy=no-user-gesture-required", "--disable-background-networking",
            "--disable-component-update", "--disable-sync", "--no-first-run",
            f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=6000"]
    try:
        proc = subprocess.run([*base, "--dump-dom", probe.as_uri()], capture_output=True,
                              text=True, timeout=120, check=False)
        shot = tmp_path / "shot.png"
        subprocess.run([*base, "--window-size=1280,900", f"--screenshot={shot}",
                        probe.as_uri()], capture_output=True, timeout=120, check=False)
    finally:
        probe.unlink()
    title = re.search(r"<title>([^<]*)</title>", proc.stdout)
    assert title is not None, proc.stderr[-2000:]
    width, height = layout_for(480, 270).size
    played = re.fullmatch(r"played (\d+\.\d+) (\d+)x(\d+)", title.group(1))
    assert played, title.group(1)
    assert float(played.group(1)) > 0.5  # the clock ran: it played
    assert (int(played.group(2)), int(played.group(3))) == (width, height)
    img = cv2.imread(str(shot))
    assert img is not None and len(np.unique(img.reshape(-1, 3), axis=0)) > 200


# --------------------------------------------------------------------------- bad input


def _clip(path, n: int, size: tuple[int, int]) -> None:
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, size)
    for k in range(n):
        w.write(np.full((size[1], size[0], 3), 10 + k, np.uint8))
    w.release()


@pytest.fixture
def bad_world(short_build, tmp_path):
    sample, built = short_build
    out = tmp_path / "B"
    shutil.copytree(built, out)
    (tmp_path / "empty").mkdir()
    _clip(tmp_path / "small.mp4", 30, (320, 180))
    _clip(tmp_path / "short.mp4", 20, (480, 270))
    return {"video": sample.video, "B": out, "tmp": tmp_path}


def _request(w, **kw):
    from vid2sim.app.rendering import RenderRequest

    build = kw.pop("build_dir", w["B"])
    return RenderRequest(build_dir=build, out=kw.pop("out", build / "replay.mp4"), **kw)


def _argv(req) -> list[str]:
    argv = ["render", str(req.build_dir), "--out", str(req.out)]
    for flag, value in (("--video", req.video), ("--from", req.t_from_s), ("--to", req.t_to_s),
                        ("--fps", req.fps)):
        if value is not None:
            argv += [flag, str(value)]
    return argv


#: name -> (RenderRequest fields, error class)
CASES = {
    "no scenario.json": (lambda w: {"build_dir": w["tmp"] / "empty"}, MissingInputError),
    "no such folder": (lambda w: {"build_dir": w["tmp"] / "nowhere",
                                  "out": w["tmp"] / "r.mp4"}, MissingInputError),
    "video of another size": (lambda w: {"video": w["tmp"] / "small.mp4"},
                              InconsistentInputError),
    "video of another length": (lambda w: {"video": w["tmp"] / "short.mp4"},
                                InconsistentInputError),
    "not an mp4": (lambda w: {"out": w["tmp"] / "r.avi"}, OutputError),
    "from beyond the clip": (lambda w: {"video": w["video"], "t_from_s": 5.0},
                             InconsistentInputError),
    "to before from": (lambda w: {"t_from_s": 2.0, "t_to_s": 1.0}, ImpossibleValueError),
    "fps not finite": (lambda w: {"fps": float("nan")}, ImpossibleValueError),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_one_error_line_exit_2_nothing_written(case, bad_world, capsys):
    fields, kind = CASES[case]
    request = _request(bad_world, **fields(bad_world))
    before = _snapshot(bad_world["tmp"])
    code = main(_argv(request))
    err = capsys.readouterr().err
    assert code == 2, err
    _assert_one_error_line(err)
    assert _snapshot(bad_world["tmp"]) == before
    from vid2sim.app.rendering import run_render

    with pytest.raises(kind):
        run_render(request)
    assert _snapshot(bad_world["tmp"]) == before


def test_unwritable_output_exit_2_before_any_drawing(bad_world, capsys):
    before = _snapshot(bad_world["tmp"])
    with read_only(bad_world["B"]):
        code = main(["render", str(bad_world["B"]), "--video", str(bad_world["video"])])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "cannot write" in _assert_one_error_line(err)
    assert _snapshot(bad_world["tmp"]) == before


def test_disk_full_keeps_the_old_replay(bad_world):
    # every write past 64 kB fails as on a full disk (RLIMIT_FSIZE: EFBIG)
    import resource

    before = _snapshot(bad_world["tmp"])

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536))

    env = {**os.environ, "PYTHONPATH": str(REPO)}
    r = subprocess.run([sys.executable, "-m", "vid2sim", "-q", "render", str(bad_world["B"]),
                        "--video", str(bad_world["video"])], capture_output=True, text=True,
                       env=env, preexec_fn=limit, timeout=600, check=False)
    assert r.returncode == 2, r.stderr
    assert "free some space" in _assert_one_error_line(r.stderr)
    assert _snapshot(bad_world["tmp"]) == before
