"""``vid2sim calibrate``: bad input is one error line and exit 2 with nothing written; on the
real KITTI raw 0001 drive the camera file's focal length and height are recovered."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from vid2sim.base.errors import FormatError, ImpossibleValueError, MissingInputError
from vid2sim.cli import main
from vid2sim.core.camera import load_camera

W, H = 320, 180


def _video(path: Path, n: int, dark: bool = False) -> Path:
    rng = np.random.default_rng(0)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (W, H))
    for _ in range(n):
        level = 4 if dark else 110
        frame = np.clip(rng.normal(level, 3, (H, W, 3)), 0, 255).astype(np.uint8)
        writer.write(frame)
    writer.release()
    return path


def _run(capsys, *args) -> tuple[int, str]:
    code = main(["-q", "calibrate", *map(str, args)])
    return code, capsys.readouterr().err


def test_too_dark_is_an_error_and_nothing_is_written(tmp_path, capsys, raised):
    out = tmp_path / "camera.yaml"
    code, err = _run(capsys, _video(tmp_path / "dark.mp4", 40, dark=True), "--out", out)
    assert code == 2 and raised == [MissingInputError]
    assert err.startswith("error:") and "dark" in err and "Traceback" not in err
    assert not out.exists()


def test_too_short_is_an_error_and_nothing_is_written(tmp_path, capsys, raised):
    out = tmp_path / "camera.yaml"
    code, err = _run(capsys, _video(tmp_path / "short.mp4", 3), "--out", out)
    assert code == 2 and err.startswith("error:") and raised == [MissingInputError]
    assert not out.exists()


@pytest.mark.parametrize(("prior", "kind"), [
    ("fx: -3\n", ImpossibleValueError), ("height_m: 40\n", ImpossibleValueError),
    ("pitch_deg: 1e6\n", ImpossibleValueError), ("fx: .nan\n", ImpossibleValueError),
    ("dist: [3.0, 0.0]\n", ImpossibleValueError), ("fx: wide\n", FormatError)])
def test_impossible_prior_is_an_error(tmp_path, capsys, raised, prior, kind):
    path = tmp_path / "prior.yaml"
    path.write_text(prior)
    out = tmp_path / "camera.yaml"
    code, err = _run(capsys, _video(tmp_path / "v.mp4", 40), "--camera", path, "--out", out)
    assert code == 2 and err.startswith("error:") and "Traceback" not in err
    assert raised == [kind]
    assert not out.exists()


# --------------------------------------------------------------------------- real data


@pytest.fixture(scope="module")
def kitti_calibration(kitti_raw_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("calib") / "camera.yaml"
    assert main(["-q", "calibrate", str(kitti_raw_dir / "video.mp4"), "--gps",
                 str(kitti_raw_dir), "--out", str(out)]) == 0
    return out


def test_kitti_without_its_camera_file(kitti_raw_dir, kitti_calibration):
    truth = load_camera(kitti_raw_dir / "camera.yaml")
    est = load_camera(kitti_calibration)
    assert abs(est.fx / truth.fx - 1) < 0.05
    assert abs(est.height_m / truth.height_m - 1) < 0.10
    assert abs(est.horizon_y_px(truth.cx) - truth.horizon_y_px()) < 5.0
    rec = yaml.safe_load(kitti_calibration.read_text())
    assert rec["source"]["fx"].startswith("estimated")
    assert rec["source"]["height_m"].startswith("estimated")
    assert 0 < rec["std"]["fx"] < 0.05 * est.fx and 0 < rec["std"]["height_m"] < 0.2
    assert rec["calibrated_from"] and rec["frames"]


def test_gps_that_never_moves_is_not_used_for_the_scale(kitti_raw_dir, tmp_path, capsys):
    gps = tmp_path / "parked.csv"
    gps.write_text("t,lat,lon\n" + "".join(f"{1.7e9 + i:.1f},49.0,8.4\n" for i in range(20)))
    out = tmp_path / "camera.yaml"
    code = main(["calibrate", str(kitti_raw_dir / "video.mp4"), "--gps", str(gps), "--out",
                 str(out)])
    text = capsys.readouterr().out
    assert code == 0
    assert "warning: the GPS never moves" in text
    rec = yaml.safe_load(out.read_text())
    assert not rec["source"]["height_m"].startswith("estimated (GPS")
    assert math.isfinite(rec["fx"])


def test_a_partial_prior_is_honoured(kitti_raw_dir, tmp_path):
    prior = tmp_path / "prior.yaml"
    prior.write_text("height_m: 1.65\n")
    out = tmp_path / "camera.yaml"
    assert main(["-q", "calibrate", str(kitti_raw_dir / "video.mp4"), "--gps",
                 str(kitti_raw_dir), "--camera", str(prior), "--out", str(out)]) == 0
    rec = yaml.safe_load(out.read_text())
    assert rec["height_m"] == 1.65 and rec["source"]["height_m"] == "camera file"
    assert abs(rec["fx"] / 721.5377 - 1) < 0.05
