"""Split recordings: two consecutive segments cut (stream copy, at a keyframe) from the real
KITTI 0001 video give one scenario whose tracks match the uncut recording's; segments of two
drives or two cameras are refused."""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

from vid2sim.app.segments import order_segments, read_segment
from vid2sim.base.errors import InconsistentInputError
from vid2sim.cli import main

START = datetime(2011, 9, 26, 13, 2, 25, tzinfo=UTC).timestamp()


def cut(src: Path, dst: Path, lo: int, hi: int, start_utc_s: float) -> Path:
    """Video packets lo..hi-1 of ``src`` (lo a keyframe) copied into ``dst``, its
    ``creation_time`` the segment's start, as a dash-cam writes each segment."""
    import av

    with av.open(str(src)) as inp, av.open(str(dst), "w", format="mp4") as out:
        out.metadata["creation_time"] = datetime.fromtimestamp(start_utc_s, UTC).strftime(
            "%Y-%m-%dT%H:%M:%S.000000Z")
        vin = inp.streams.video[0]
        vout = out.add_stream_from_template(vin)
        packets = [p for p in inp.demux(vin) if p.dts is not None]
        shift = packets[lo].dts
        for p in packets[lo:hi]:
            p.pts -= shift
            p.dts -= shift
            p.stream = vout
            out.mux(p)
    return dst


def _tracks(out: Path) -> tuple[int, dict[int, float]]:
    scenario = json.loads((out / "scenario.json").read_text())
    rows = (out / "tracks.csv").read_text().splitlines()
    head = rows[0].split(",")
    ranges: dict[int, list[float]] = {}
    for line in rows[1:]:
        cells = dict(zip(head, line.split(","), strict=True))
        if cells.get("range_m"):
            ranges.setdefault(int(cells["track_id"]), []).append(float(cells["range_m"]))
    return len(scenario["actors"]), {k: float(np.median(v)) for k, v in ranges.items()}


def test_two_segments_build_like_the_uncut_recording(kitti_raw_dir, model_dir, tmp_path):
    video = kitti_raw_dir / "video.mp4"
    seg1 = cut(video, tmp_path / "0001_A.MP4", 0, 48, START)  # 4.8 s
    seg2 = cut(video, tmp_path / "0001_B.MP4", 48, 108, START + 4.8)
    common = ["--camera", str(kitti_raw_dir / "camera.yaml"), "--model-dir", str(model_dir),
              "--offline"]
    assert main(["-q", "build", str(video), *common, "--out", str(tmp_path / "uncut")]) == 0
    # given out of order: the embedded start times order them
    assert main(["-q", "build", str(seg2), str(seg1), *common,
                 "--out", str(tmp_path / "joined")]) == 0
    n_uncut, r_uncut = _tracks(tmp_path / "uncut")
    n_joined, r_joined = _tracks(tmp_path / "joined")
    assert abs(n_joined - n_uncut) <= 1
    assert sorted(r_uncut) == sorted(r_joined)
    for tid, r in r_uncut.items():
        assert r_joined[tid] == pytest.approx(r, rel=0.01)
    scenario = json.loads((tmp_path / "joined" / "scenario.json").read_text())
    assert any("2 segments joined" in a for a in scenario["source"]["assumptions"])
    assert not list(tmp_path.glob(".vid2sim-join.*"))  # the joined copy is removed


def test_segments_of_two_drives_are_refused(kitti_raw_dir, tmp_path, capsys, raised):
    video = kitti_raw_dir / "video.mp4"
    seg1 = cut(video, tmp_path / "A.MP4", 0, 48, START)
    seg2 = cut(video, tmp_path / "B.MP4", 48, 108, START + 3600)  # an hour later
    with pytest.raises(InconsistentInputError):
        order_segments([read_segment(seg1), read_segment(seg2)])
    out = tmp_path / "out"
    assert main(["build", str(seg1), str(seg2), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {seg2}: ")
    assert raised == [InconsistentInputError]  # not the segment after the first
    assert not out.exists()


def test_batch_builds_a_row_of_segments_as_one_drive(kitti_raw_dir, model_dir, tmp_path):
    video = kitti_raw_dir / "video.mp4"
    drive = tmp_path / "card" / "drive1"
    drive.mkdir(parents=True)
    cut(video, drive / "0001_A.MP4", 0, 48, START)
    cut(video, drive / "0001_B.MP4", 48, 108, START + 4.8)
    manifest = tmp_path / "card" / "manifest.csv"
    manifest.write_text("video,name,camera\ndrive1,drive1,"
                        f"{kitti_raw_dir / 'camera.yaml'}\n")
    out = tmp_path / "batch"
    assert main(["-q", "batch", str(manifest), "--out", str(out), "--model-dir",
                 str(model_dir), "--offline"]) == 0
    scenario = json.loads((out / "drive1" / "scenario.json").read_text())
    assert any("2 segments joined" in a for a in scenario["source"]["assumptions"])
