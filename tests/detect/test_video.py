"""Streamed video input: frame count, timestamps, skipping, image folders, errors."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from vid2sim.base.errors import FormatError, ImpossibleValueError, MissingInputError
from vid2sim.detect.video import iter_frames, video_info


def _write_video(path: Path, n: int = 12, fps: float = 5.0, size=(64, 48)) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
    assert writer.isOpened()
    for i in range(n):
        img = np.full((size[1], size[0], 3), 10 * i, dtype=np.uint8)
        writer.write(img)
    writer.release()
    return path


def test_video_frames_and_times(tmp_path):
    video = _write_video(tmp_path / "v.mp4", n=12, fps=5.0)
    info = video_info(video)
    assert (info.width, info.height, info.n_frames) == (64, 48, 12)
    assert info.fps == pytest.approx(5.0)
    frames = list(iter_frames(video))
    assert [f.index for f in frames] == list(range(12))
    # 5 frames/s: frame i at i * 0.2 s, from the container clock
    assert [f.t_s for f in frames] == pytest.approx([0.2 * i for i in range(12)], abs=1e-3)
    assert all(f.image_bgr.shape == (48, 64, 3) for f in frames)
    # brightness ramp survives the codec: frames come in order
    means = [float(f.image_bgr.mean()) for f in frames]
    assert means == sorted(means)


def test_every_skips_decoding_but_keeps_time_base(tmp_path):
    video = _write_video(tmp_path / "v.mp4", n=10, fps=10.0)
    frames = list(iter_frames(video, every=3))
    assert len(frames) == 10
    decoded = [f.index for f in frames if f.image_bgr is not None]
    assert decoded == [0, 3, 6, 9]
    assert frames[4].t_s == pytest.approx(0.4, abs=1e-3)


def test_only_decodes_the_given_frames_on_the_same_clock(tmp_path):
    video = _write_video(tmp_path / "v.mp4", n=10, fps=10.0)
    every = list(iter_frames(video))
    some = list(iter_frames(video, only={2, 7}))
    assert [f.index for f in some if f.image_bgr is not None] == [2, 7]
    assert [f.t_s for f in some] == pytest.approx([f.t_s for f in every])
    assert np.array_equal(some[7].image_bgr, every[7].image_bgr)
    for i in (0, 1, 2):
        cv2.imwrite(str(tmp_path / f"{i:06d}.png"), np.full((8, 16, 3), 50 * i, np.uint8))
    folder = [f for f in iter_frames(tmp_path, only=[1]) if f.image_bgr is not None]
    assert [(f.index, int(f.image_bgr.mean())) for f in folder] == [(1, 50)]


def test_image_folder_sorted_by_name_at_given_fps(tmp_path):
    for i in (2, 0, 1):
        cv2.imwrite(str(tmp_path / f"{i:06d}.png"), np.full((8, 16, 3), 50 * i, np.uint8))
    (tmp_path / "notes.txt").write_text("not an image")
    frames = list(iter_frames(tmp_path, fps=4.0))
    assert [f.t_s for f in frames] == pytest.approx([0.0, 0.25, 0.5])
    assert [int(f.image_bgr.mean()) for f in frames] == [0, 50, 100]
    assert video_info(tmp_path).n_frames == 3
    assert video_info(tmp_path).fps == 10.0  # default for folders


def test_bad_inputs_raise_input_error(tmp_path):
    with pytest.raises(MissingInputError):
        list(iter_frames(tmp_path / "missing.mp4"))
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(b"this is not a video")
    with pytest.raises(FormatError):
        video_info(junk)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(MissingInputError):  # a folder without images
        list(iter_frames(empty))
    with pytest.raises(ImpossibleValueError, match="--detect-every"):
        list(iter_frames(_write_video(tmp_path / "v.mp4"), every=0))


def test_kitti_raw_video(kitti_raw_dir):
    video = kitti_raw_dir / "video.mp4"
    info = video_info(video)
    assert (info.width, info.height, info.n_frames) == (1242, 374, 108)
    times = [f.t_s for f in iter_frames(video, every=1000)]
    assert len(times) == 108
    assert np.diff(times) == pytest.approx(np.full(107, 0.1), abs=1e-3)
