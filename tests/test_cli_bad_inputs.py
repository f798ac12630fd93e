"""Issue 16's table through the CLI: every class of bad input exits 2 with one ``error:`` line,
no traceback, the output location untouched and no staging folder left behind; and what must
NOT be an error (a corrupt frame, a GPS gap, an output on another filesystem) is reported and
written in place. SIGTERM and a full disk run in real subprocesses."""

from __future__ import annotations

import contextlib
import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from vid2sim.base.errors import (
    FormatError,
    ImpossibleValueError,
    InconsistentInputError,
    InputError,
    MissingInputError,
    OutputError,
    ScenarioError,
)
from vid2sim.base.fileio import STAGING_PREFIX
from vid2sim.cli import main

REPO = Path(__file__).resolve().parents[1]
T0 = 1_700_000_000.0
W, H, N_FRAMES, FPS = 320, 180, 40, 10.0

CAMERA_YAML = f"""\
image_width: {W}
image_height: {H}
fx: 200.0
fy: 200.0
cx: {(W - 1) / 2}
cy: {(H - 1) / 2}
dist: [0.0, 0.0, 0.0, 0.0, 0.0]
height_m: 1.4
pitch_deg: 0.0
yaw_deg: 0.0
roll_deg: 0.0
"""


# --------------------------------------------------------------------------- inputs


def _frame(i: int, rng: np.random.Generator) -> np.ndarray:
    """A road-like frame: sky, grey road, a dark car ahead drifting left; noise so that the
    video has some bytes to damage."""
    img = np.full((H, W, 3), 110, np.uint8)
    img[: H // 2] = (200, 170, 140)
    x = 150 - i
    img[95:125, x:x + 40] = 30
    noise = rng.integers(0, 40, (H, W, 3), dtype=np.uint8)
    return cv2.add(img, noise)


def write_video(path: Path, n: int = N_FRAMES) -> Path:
    rng = np.random.default_rng(0)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), FPS, (W, H))
    for i in range(n):
        writer.write(_frame(i, rng))
    writer.release()
    return path


def gps_csv(n: int = 60, gap_after: int | None = None, gap_s: float = 0.0) -> str:
    rows = ["t,lat,lon"]
    for i in range(n):
        t = T0 + i / FPS + (gap_s if gap_after is not None and i > gap_after else 0.0)
        # 1 m per fix north, 10 m/s: across a gap the car drove on (a clock that jumps
        # while the fixes stay 1 m apart is re-timed, not a gap)
        rows.append(f"{t:.2f},{60.17 + (t - T0) * FPS * 9e-6:.7f},24.94")
    return "\n".join(rows) + "\n"


def mot_rows(n: int = N_FRAMES, box: str | None = None) -> str:
    rows = [f"{i + 1},1,{150 - i},95,40,30,0.9,car" for i in range(n)]
    if box is not None:
        rows[n // 2] = f"{n // 2 + 1},1,{box},0.9,car"
    return "\n".join(rows) + "\n"


def keyframes_json(frames: list[int]) -> str:
    return json.dumps([{"name": f"{f:06d}.jpg", "frameIndex": f, "labels": [
        {"category": "car", "box2d": {"x1": 150 - f, "y1": 95, "x2": 190 - f, "y2": 125}}]}
        for f in frames])


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("inputs")
    files = {"video": write_video(d / "video.mp4")}
    for name, text in (("gps", gps_csv()), ("det", mot_rows()), ("camera", CAMERA_YAML),
                       ("keyframes", keyframes_json([0, 20]))):
        suffix = {"gps": ".csv", "det": ".txt", "camera": ".yaml", "keyframes": ".json"}[name]
        files[name] = d / f"{name}{suffix}"
        files[name].write_text(text)
    # a good scenario to export and evaluate: one build of the inputs above
    out = d / "good_build"
    assert main(["-q", "build", str(files["video"]), "--gps", str(files["gps"]), "--camera",
                 str(files["camera"]), "--detections", str(files["det"]), "--offline",
                 "--out", str(out)]) == 0
    files["scenario"] = out / "scenario.json"
    return files


def _scenario_with(world, tmp: Path, mutate) -> Path:
    data = json.loads(world["scenario"].read_text())
    mutate(data)
    path = tmp / "bad_scenario.json"
    path.write_text(json.dumps(data))
    return path


def _write(tmp: Path, name: str, text: str | bytes) -> Path:
    path = tmp / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return path


def _mixed_folder(tmp: Path) -> Path:
    folder = tmp / "frames"
    folder.mkdir()
    rng = np.random.default_rng(1)
    for i in range(6):
        img = _frame(i, rng)
        if i == 4:
            img = cv2.resize(img, (W // 2, H // 2))
        cv2.imwrite(str(folder / f"{i:06d}.png"), img)
    return folder


def _camera_with(tmp: Path, line: str) -> Path:
    key = line.split(":")[0]
    text = "\n".join(line if r.startswith(key + ":") else r for r in CAMERA_YAML.splitlines())
    return _write(tmp, "camera.yaml", text + "\n")


# Each case: (id, the error's class, command builder). A builder gets (world, tmp folder, out
# folder, out file) and returns the argument list. Out folder and out file hold an earlier
# run's outputs. A scenario over the size limit is a plain InputError: no named class fits.
CASES = [
    # GPS: fixes that cannot be one drive, times that are not times
    ("gps-alternating-1000km", InconsistentInputError, lambda w, t, o, f: [
        "trace", str(_write(t, "alt.csv", "t,lat,lon\n" + "".join(
            f"{T0 + i},{60.17 if i % 2 else 51.5},{24.94 if i % 2 else -0.12}\n"
            for i in range(40)))), "--out", str(f)]),
    ("gps-alternating-build", InconsistentInputError, lambda w, t, o, f: [
        "build", str(w["video"]), "--gps", str(_write(t, "alt.csv", "t,lat,lon\n" + "".join(
            f"{T0 + i * 0.1},{60.17 if i % 2 else 51.5},{24.94 if i % 2 else -0.12}\n"
            for i in range(60)))), "--detections", str(w["det"]), "--offline", "--out", str(o)]),
    ("gps-time-1e300", ImpossibleValueError, lambda w, t, o, f: [
        "trace", str(_write(t, "t.csv", "t,lat,lon\n0,60.17,24.94\n1e300,60.171,24.94\n")),
        "--out", str(f)]),
    ("gps-nan-position", ImpossibleValueError, lambda w, t, o, f: [
        "road", str(_write(t, "n.csv", "t,lat,lon\n0,60.17,24.94\n1,nan,24.94\n")),
        "--no-download", "--out", str(f)]),
    ("gps-json-100000-deep", FormatError, lambda w, t, o, f: [
        "trace", str(_write(t, "deep.json", '{"locations": ' + "[" * 100_000 + "]" * 100_000
                            + "}")), "--out", str(f)]),
    # camera: every number finite and physical
    ("camera-fx-nan", ImpossibleValueError, lambda w, t, o, f: [
        "track", str(w["video"]), "--camera", str(_camera_with(t, "fx: .nan")),
        "--detections", str(w["det"]), "--out", str(f)]),
    ("camera-cx-inf", ImpossibleValueError, lambda w, t, o, f: [
        "build", str(w["video"]), "--camera", str(_camera_with(t, "cx: .inf")),
        "--detections", str(w["det"]), "--offline", "--out", str(o)]),
    ("camera-pitch-1e6", ImpossibleValueError, lambda w, t, o, f: [
        "track", str(w["video"]), "--camera", str(_camera_with(t, "pitch_deg: 1e6")),
        "--detections", str(w["det"]), "--out", str(f)]),
    # detections: non-finite, degenerate, binary, deep
    ("detections-nan-box", ImpossibleValueError, lambda w, t, o, f: [
        "detect", str(w["video"]), "--detections",
        str(_write(t, "d.txt", mot_rows(box="nan,95,40,30"))), "--out", str(f)]),
    ("detections-inf-box-build", ImpossibleValueError, lambda w, t, o, f: [
        "build", str(w["video"]), "--detections",
        str(_write(t, "d.txt", mot_rows(box="10,95,inf,30"))), "--offline", "--out", str(o)]),
    ("detections-zero-width", ImpossibleValueError, lambda w, t, o, f: [
        "track", str(w["video"]), "--detections",
        str(_write(t, "d.txt", mot_rows(box="10,95,0,30"))), "--out", str(f)]),
    ("detections-binary", FormatError, lambda w, t, o, f: [
        "detect", str(w["video"]), "--detections",
        str(_write(t, "d.csv", bytes(range(256)) * 16)), "--out", str(f)]),
    ("detections-json-100000-deep", FormatError, lambda w, t, o, f: [
        "detect", str(w["video"]), "--detections",
        str(_write(t, "d.json", "[" * 100_000 + "]" * 100_000)), "--out", str(f)]),
    # keyframes beyond the video: before any detection
    ("keyframes-beyond-video", InconsistentInputError, lambda w, t, o, f: [
        "build", str(w["video"]), "--detections", str(w["det"]), "--keyframes",
        str(_write(t, "k.json", keyframes_json([5000, 99_999]))), "--offline", "--out", str(o)]),
    ("keyframes-beyond-video-eval", InconsistentInputError, lambda w, t, o, f: [
        "eval", str(w["scenario"]), "--keyframes",
        str(_write(t, "k.json", keyframes_json([5000, 99_999]))), "--video", str(w["video"]),
        "--out", str(o)]),
    # tracklet keyframes: broken XML, calibration missing, a NaN pose
    ("keyframes-tracklets-broken-xml", MissingInputError, lambda w, t, o, f: [
        "eval", str(w["scenario"]), "--keyframes",
        str(_write(t, "tracklet_labels.xml", "<boost_serialization><tracklets><count>1")),
        "--out", str(o)]),
    ("keyframes-tracklets-no-calibration", MissingInputError, lambda w, t, o, f: [
        "build", str(w["video"]), "--detections", str(w["det"]), "--keyframes",
        str(_write(t, "tracklet_labels.xml", _tracklets_xml("10.0"))), "--offline",
        "--out", str(o)]),
    ("keyframes-tracklets-nan-pose", ImpossibleValueError, lambda w, t, o, f: [
        "eval", str(w["scenario"]), "--keyframes",
        str(_write(t, "tracklet_labels.xml", _tracklets_xml("nan"))),
        "--keyframe-calib", str(_kitti_calib(t)), "--out", str(o)]),
    ("keyframes-tracklets-calib-folder-missing", MissingInputError, lambda w, t, o, f: [
        "eval", str(w["scenario"]), "--keyframes",
        str(_write(t, "tracklet_labels.xml", _tracklets_xml("10.0"))),
        "--keyframe-calib", str(t / "nowhere"), "--out", str(o)]),
    # frames: a folder of images of different sizes
    ("frames-mixed-sizes", InconsistentInputError, lambda w, t, o, f: [
        "detect", str(_mixed_folder(t)), "--detections", str(w["det"]), "--out", str(f)]),
    ("frames-mixed-sizes-build", InconsistentInputError, lambda w, t, o, f: [
        "build", str(_mixed_folder(t)), "--detections", str(w["det"]), "--offline",
        "--out", str(o)]),
    # scenarios: degenerate roads, limits, damage
    ("scenario-degenerate-road-highway-env", ScenarioError, lambda w, t, o, f: [
        "export", str(_scenario_with(w, t, lambda d: d["roads"][0].update(
            centerline=[[3.0, 4.0], [3.0, 4.0]]))), "--format", "highway-env", "--out", str(o)]),
    ("scenario-road-turns-back-openscenario", ScenarioError, lambda w, t, o, f: [
        "export", str(_scenario_with(w, t, lambda d: d["roads"][0].update(
            centerline=[[0.0, 0.0], [80.0, 0.0], [0.0, 0.0]]))), "--format", "openscenario",
        "--out", str(o)]),
    ("scenario-lanes-1e9", ScenarioError, lambda w, t, o, f: [
        "export", str(_scenario_with(w, t, lambda d: d["roads"][0].update(lanes=10**9))),
        "--format", "highway-env", "--out", str(o)]),
    ("scenario-speed-1e6", ScenarioError, lambda w, t, o, f: [
        "export", str(_scenario_with(w, t, lambda d: d["ego"]["trajectory"][0].update(
            speed=1e6))), "--format", "openscenario", "--out", str(o)]),
    ("scenario-over-size-limit", InputError, lambda w, t, o, f: [
        "export", str(_sparse(t / "huge.json", 70 * 2**20)), "--format", "openscenario",
        "--out", str(o)]),
    ("scenario-json-100000-deep", FormatError, lambda w, t, o, f: [
        "eval", str(_write(t, "s.json", "[" * 100_000 + "]" * 100_000)), "--keyframes",
        str(w["keyframes"]), "--out", str(o)]),
    ("keyframes-json-100000-deep", FormatError, lambda w, t, o, f: [
        "eval", str(w["scenario"]), "--keyframes",
        str(_write(t, "k.json", "[" * 100_000 + "]" * 100_000)), "--out", str(o)]),
]


def _tracklets_xml(tx: str) -> str:
    """A KITTI tracklet file with one car and one pose at ``tx`` metres ahead."""
    pose = (f"<item><tx>{tx}</tx><ty>0</ty><tz>-1.7</tz><rx>0</rx><ry>0</ry><rz>0</rz>"
            "<state>1</state><occlusion>0</occlusion><truncation>0</truncation></item>")
    return ("<?xml version='1.0'?><boost_serialization><tracklets><count>1</count><item>"
            "<objectType>Car</objectType><h>1.5</h><w>1.8</w><l>4.0</l>"
            f"<first_frame>0</first_frame><poses><count>1</count>{pose}</poses></item>"
            "</tracklets></boost_serialization>")


def _kitti_calib(tmp: Path) -> Path:
    folder = tmp / "calib"
    folder.mkdir(exist_ok=True)
    _write(folder, "calib_velo_to_cam.txt", "R: 0 -1 0 0 0 -1 1 0 0\nT: 0 0 0\n")
    _write(folder, "calib_cam_to_cam.txt", "R_rect_00: 1 0 0 0 1 0 0 0 1\n"
           "P_rect_00: 200 0 160 0 0 200 90 0 0 0 1 0\n")
    return folder


def _sparse(path: Path, size: int) -> Path:
    with open(path, "wb") as fh:
        fh.truncate(size)
    return path


def _snapshot(root: Path) -> dict[str, bytes | None]:
    """Every entry under ``root``: relative path -> content (None for a folder)."""
    return {str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes())
            for p in sorted(root.rglob("*"))}


def _earlier_outputs(tmp: Path) -> tuple[Path, Path]:
    out_dir = tmp / "out"
    out_dir.mkdir()
    (out_dir / "scenario.json").write_text("an earlier build\n")
    (out_dir / "metrics.json").write_text("{}\n")
    (out_dir / "notes.txt").write_text("the user's own file\n")
    out_file = tmp / "out.csv"
    out_file.write_text("an earlier run\n")
    return out_dir, out_file


def _assert_one_error_line(err: str) -> str:
    assert "Traceback" not in err and "internal error" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("error: ")]
    assert len(errors) == 1 and lines[-1] == errors[0], err
    return errors[0]


@pytest.mark.parametrize("error, case", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_exit_2_one_line_output_untouched(error, case, world, tmp_path, capsys,
                                                    raised):
    out_dir, out_file = _earlier_outputs(tmp_path)
    args = case(world, tmp_path, out_dir, out_file)
    before = _snapshot(tmp_path)
    code = main(args)
    err = capsys.readouterr().err
    assert code == 2, err
    _assert_one_error_line(err)
    assert raised == [error]
    assert _snapshot(tmp_path) == before  # nothing written, nothing staged left behind


# --------------------------------------------------------------------------- output location


@contextlib.contextmanager
def read_only(folder: Path):
    """``folder`` made unwritable: permission bits, or for root (who ignores them) the
    immutable attribute; skips where neither works."""
    if os.geteuid() != 0:
        folder.chmod(0o555)
        try:
            yield
        finally:
            folder.chmod(0o755)
        return
    r = subprocess.run(["chattr", "+i", str(folder)], capture_output=True, check=False)
    if r.returncode != 0:
        pytest.skip(f"running as root and chattr +i is not available: {r.stderr.decode()}")
    try:
        yield
    finally:
        subprocess.run(["chattr", "-i", str(folder)], check=False)


@pytest.mark.parametrize("command", ["trace", "build", "export", "eval"])
def test_read_only_output_exit_2_before_any_work(command, world, tmp_path, capsys, raised):
    out_dir, _ = _earlier_outputs(tmp_path)
    args = {
        "trace": ["trace", str(world["gps"]), "--out", str(out_dir / "ego.csv")],
        "build": ["build", str(world["video"]), "--detections", str(world["det"]), "--offline",
                  "--out", str(out_dir)],
        "export": ["export", str(world["scenario"]), "--format", "openscenario", "--out",
                   str(out_dir)],
        "eval": ["eval", str(world["scenario"]), "--keyframes", str(world["keyframes"]),
                 "--out", str(out_dir)],
    }[command]
    before = _snapshot(tmp_path)
    with read_only(out_dir):
        t0 = time.perf_counter()
        code = main(args)
        elapsed = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert code == 2, err
    line = _assert_one_error_line(err)
    assert raised == [OutputError] and line.startswith(f"error: {out_dir}")
    assert _snapshot(tmp_path) == before
    assert elapsed < 60  # a refusal, not a run (generous: a shared 2-core machine)


def _run_cli(args: list[str], file_size_limit: int | None = None, **kw):
    def limit():
        if file_size_limit is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (file_size_limit, file_size_limit))

    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "vid2sim", *args], capture_output=True,
                          text=True, env=env, preexec_fn=limit, timeout=600, check=False, **kw)


@pytest.mark.parametrize("command", ["trace", "build"])
def test_disk_full_exit_2_old_outputs_kept(command, world, tmp_path):
    # A file-size limit (RLIMIT_FSIZE) makes every write past 4 kB fail as a full disk does
    # (EFBIG instead of ENOSPC: the same path through the code, no root or tmpfs needed).
    out_dir, out_file = _earlier_outputs(tmp_path)
    args = {"trace": ["trace", str(world["gps"]), "--rate", "100", "--out", str(out_file)],
            "build": ["-q", "build", str(world["video"]), "--detections", str(world["det"]),
                      "--offline", "--out", str(out_dir)]}[command]
    before = _snapshot(tmp_path)
    r = _run_cli(args, file_size_limit=4096)
    assert r.returncode == 2, r.stderr
    line = _assert_one_error_line(r.stderr)
    assert "cannot write" in line and "free some space" in line
    assert _snapshot(tmp_path) == before


def test_output_on_another_filesystem_is_written_in_place(world, tmp_path, capsys):
    # --out a link to a folder on another filesystem (EXDEV for a rename from beside the
    # link): staged on the output's own filesystem, so the build succeeds.
    shm = Path("/dev/shm")
    if not shm.is_dir() or shm.stat().st_dev == tmp_path.stat().st_dev:
        pytest.skip("no second filesystem (/dev/shm) beside the test folder")
    target = Path(shm / f"vid2sim-test-{os.getpid()}")
    target.mkdir()
    try:
        (target / "metrics.json").write_text("{}\n")  # stale: a build owns its folder
        link = tmp_path / "out"
        link.symlink_to(target)
        assert main(["-q", "build", str(world["video"]), "--detections", str(world["det"]),
                     "--offline", "--out", str(link)]) == 0, capsys.readouterr().err
        names = {p.name for p in target.iterdir()}
        assert {"scenario.json", "tracks.csv", "report.html"} <= names
        assert "metrics.json" not in names
        assert not [n for n in names if n.startswith(STAGING_PREFIX)]
        assert link.is_symlink()
        assert [p.name for p in tmp_path.iterdir()] == ["out"]
        # a new folder below the link, and the highway-env export into the link
        assert main(["-q", "export", str(target / "scenario.json"), "--format", "openscenario",
                     "--out", str(link / "sub" / "x")]) == 0
        assert (target / "sub" / "x" / "scenario.xosc").exists()
    finally:
        import shutil

        shutil.rmtree(target, ignore_errors=True)


# --------------------------------------------------------------------------- signals

_SLOW_STAGE = """
import signal, sys, time
# A shell without job control starts background jobs with SIGINT ignored, children inherit it
# and Python then installs no KeyboardInterrupt handler: put Python's own default back, so the
# test measures vid2sim and not the shell that started pytest.
signal.signal(signal.SIGINT, signal.default_int_handler)
import vid2sim.app.build as build_module
marker, stage = sys.argv[1], sys.argv[2]
real = getattr(build_module, stage)
def slow(*args, **kwargs):
    out = real(*args, **kwargs)
    open(marker, "w").write("the build is inside " + stage)
    # short sleeps, as real work returns to the interpreter often: a signal the kernel hands
    # to another thread (onnxruntime's, OpenCV's) does not cut a long sleep of this one, and
    # Python runs its handler only when the main thread next runs bytecode
    end = time.monotonic() + 120
    while time.monotonic() < end:
        time.sleep(0.05)
    return out
setattr(build_module, stage, slow)
from vid2sim.cli import main
sys.exit(main(sys.argv[3:]))
"""


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)],
                         ids=["SIGTERM", "SIGINT"])
@pytest.mark.parametrize("stage", ["detect_and_range_with", "write_openscenario"])
def test_signal_leaves_no_staging_and_old_outputs(sig, code, stage, world, tmp_path):
    # A real `vid2sim build` process, stopped by a real signal while a stage runs (detection,
    # or writing the outputs into the staging folder).
    out_dir, _ = _earlier_outputs(tmp_path)
    marker = tmp_path.parent / f"{tmp_path.name}.marker"
    before = _snapshot(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        [sys.executable, "-c", _SLOW_STAGE, str(marker), stage, "-q", "build",
         str(world["video"]), "--detections", str(world["det"]), "--offline",
         "--out", str(out_dir)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    try:
        deadline = time.monotonic() + 300
        while not marker.exists():
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "the build never reached the stage"
            time.sleep(0.1)
        assert any(p.name.startswith(STAGING_PREFIX) for p in out_dir.iterdir())
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
        marker.unlink(missing_ok=True)
    assert proc.returncode == code, err
    assert "Traceback" not in err
    assert _snapshot(tmp_path) == before


# --------------------------------------------------------------------------- not errors


def test_rebuild_owns_the_folder_no_stale_outputs(world, tmp_path, capsys):
    out = tmp_path / "out"
    base = ["-q", "build", str(world["video"]), "--gps", str(world["gps"]), "--camera",
            str(world["camera"]), "--detections", str(world["det"]), "--offline",
            "--out", str(out)]
    assert main([*base, "--keyframes", str(world["keyframes"])]) == 0, capsys.readouterr().err
    assert (out / "metrics.json").exists() and (out / "keyframes").is_dir()
    (out / "notes.txt").write_text("mine\n")
    (out / "preview.png").write_bytes(b"an export of the old scenario")
    assert main(base) == 0, capsys.readouterr().err
    names = {p.name for p in out.iterdir()}
    assert "metrics.json" not in names and "keyframes" not in names
    assert "preview.png" not in names
    assert (out / "notes.txt").read_text() == "mine\n"
    assert "scenario.json" in names and "report.html" in names
    assert not [n for n in names if n.startswith(STAGING_PREFIX)]


def test_gps_gap_is_warned_and_recorded_in_the_scenario(world, tmp_path, capsys):
    gps = _write(tmp_path, "gap.csv", gps_csv(n=80, gap_after=60, gap_s=600.0))
    out = tmp_path / "out"
    assert main(["build", str(world["video"]), "--gps", str(gps), "--detections",
                 str(world["det"]), "--offline", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "warning: GPS gap of 600 s" in text
    source = json.loads((out / "scenario.json").read_text())["source"]
    assert any("GPS gap of 600 s" in w for w in source["warnings"])
    assert any("GPS gap of 600 s" in a for a in source["assumptions"])
    assert main(["trace", str(gps), "--out", str(tmp_path / "ego.csv")]) == 0
    assert "warning:     GPS gap of 600 s" in capsys.readouterr().out


def _damaged_video(tmp: Path) -> Path:
    data = bytearray(write_video(tmp / "v.mp4", n=60).read_bytes())
    mid = len(data) // 2
    data[mid:mid + len(data) // 5] = bytes(len(data) // 5)  # a fifth of the file zeroed
    path = tmp / "damaged.mp4"
    path.write_bytes(bytes(data))
    return path


def test_corrupt_frames_are_counted_skipped_and_reported(world, tmp_path, capsys):
    video = _damaged_video(tmp_path)
    dets = _write(tmp_path, "d.txt", mot_rows(n=60))
    assert main(["detect", str(video), "--detections", str(dets), "--out",
                 str(tmp_path / "d.csv")]) == 0
    out = capsys.readouterr().out
    assert "corrupt or missing video frame(s) skipped" in out
    assert main(["-q", "build", str(video), "--detections", str(dets), "--offline", "--out",
                 str(tmp_path / "b")]) == 0
    source = json.loads((tmp_path / "b" / "scenario.json").read_text())["source"]
    assert any("corrupt or missing video frame" in w for w in source["warnings"])
