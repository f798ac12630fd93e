"""`vid2sim track` end to end on a synthetic image folder with imported (MOT) detections."""

from __future__ import annotations

import csv

import cv2
import numpy as np
import pytest
import yaml

from tests.detect.ranging.test_ranging_lanes import road_image
from vid2sim.cli import main
from vid2sim.core.camera import Camera
from vid2sim.core.tables import read_tracks_csv

CAM = Camera(image_width=640, image_height=360, fx=500.0, fy=500.0, cx=319.5, cy=179.5,
             height_m=1.4)
N_FRAMES = 30


def _lead_range_m(k: int) -> float:
    return 30.0 - 0.4 * k  # closing at 4 m/s in 10 frames/s


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """A folder of road frames and a MOT file with one car ahead closing at 4 m/s."""
    tmp_path = tmp_path_factory.mktemp("clip")
    frames = tmp_path / "frames"
    frames.mkdir()
    rows = []
    for k in range(N_FRAMES):
        cv2.imwrite(str(frames / f"{k:06d}.png"), road_image(CAM, seed=k, dash_phase_m=k))
        x1, y1, x2, y2 = CAM.project_box(np.array([_lead_range_m(k) + 2.2, 0.0]), 4.4, 1.8, 1.5)
        rows.append(f"{k + 1},1,{x1:.2f},{y1:.2f},{x2 - x1:.2f},{y2 - y1:.2f},0.9,-1,-1,-1")
    det = tmp_path / "det.txt"
    det.write_text("\n".join(rows) + "\n")
    cam_file = tmp_path / "camera.yaml"
    cam_file.write_text(yaml.safe_dump(CAM.to_dict()))
    return frames, det, cam_file


def test_track_command_writes_tracks_csv_and_plots(clip, tmp_path, capsys):
    frames, det, cam_file = clip
    out = tmp_path / "tracks.csv"
    code = main(["track", str(frames), "--camera", str(cam_file), "--detections", str(det),
                 "--plots", str(tmp_path / "plots"), "--out", str(out)])
    text = capsys.readouterr().out
    print(text)
    assert code == 0, text
    with open(out, newline="") as fh:
        header = next(csv.reader(fh))
    assert header == ["frame", "t_s", "track_id", "category", "score", "x1", "y1", "x2", "y2",
                      "range_m", "lateral_m", "range_rate_mps", "range_std_m", "is_lead", "lane"]
    boxes = read_tracks_csv(out)
    assert len(boxes) >= N_FRAMES - 3  # the tracker may confirm the track a frame or two late
    err = [abs(b.range_m - _lead_range_m(b.frame)) / _lead_range_m(b.frame) for b in boxes]
    assert np.median(err) < 0.05
    assert np.median([b.range_rate_mps for b in boxes]) == pytest.approx(-4.0, abs=0.5)
    assert all(b.is_lead for b in boxes)
    assert (tmp_path / "plots" / "lead.png").stat().st_size > 1000
    assert (tmp_path / "plots" / "topdown.png").stat().st_size > 1000
    assert "lead present on" in text and "horizon" in text and "lane markings" in text


def test_track_without_camera_says_so(clip, tmp_path, capsys):
    """Without a camera file the camera is calibrated on the clip; without GPS its scale
    cannot be, and a warning names the prior used."""
    frames, det, _ = clip
    out = tmp_path / "tracks.csv"
    assert main(["track", str(frames), "--detections", str(det), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "camera estimated" in text or "camera not calibrated" in text
    assert "warning: camera" in text and "prior" in text
    assert out.exists()


def test_track_rejects_camera_of_another_video(clip, tmp_path, capsys):
    frames, det, _ = clip
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump(Camera.default_for(1920, 1200).to_dict()))
    code = main(["track", str(frames), "--camera", str(other), "--detections", str(det),
                 "--out", str(tmp_path / "t.csv")])
    assert code == 2
    assert "1920x1200" in capsys.readouterr().err
    assert not (tmp_path / "t.csv").exists()
