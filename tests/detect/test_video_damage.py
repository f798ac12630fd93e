"""Damaged frame sources: a video whose decoder stops mid-file is resumed past the damage and
the lost frames counted; an unreadable image is counted and skipped; a folder of frames of
different sizes is an input error naming the odd frame, before any frame is decoded."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from vid2sim.base.errors import InconsistentInputError
from vid2sim.detect.video import iter_frames, video_info


def _noisy_video(path: Path, n: int = 60) -> Path:
    rng = np.random.default_rng(0)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (160, 96))
    for i in range(n):
        img = rng.integers(0, 255, (96, 160, 3), dtype=np.uint8)
        img[:, :8] = 4 * i  # the frame number, readable through the codec
        writer.write(img)
    writer.release()
    return path


def test_damaged_video_is_resumed_and_the_lost_frames_counted(tmp_path):
    video = _noisy_video(tmp_path / "v.mp4")
    data = bytearray(video.read_bytes())
    a = len(data) // 3
    data[a:a + len(data) // 4] = bytes(len(data) // 4)  # a quarter of the file zeroed
    damaged = tmp_path / "damaged.mp4"
    damaged.write_bytes(bytes(data))
    skipped: list[int] = []
    frames = list(iter_frames(damaged, skipped=skipped))
    got = [f.index for f in frames]
    assert skipped, "the damage must be noticed"
    assert sorted(got + skipped) == list(range(60))  # every declared frame: read or counted
    assert got[-1] == 59  # decoding went on after the damage
    # frames after the damage carry their own index and time (brightness stripe = index)
    for f in frames:
        assert abs(float(f.image_bgr[:, :4].mean()) - 4 * f.index) < 12
        assert f.t_s == pytest.approx(f.index / 10.0, abs=1e-3)


def test_unreadable_image_is_counted_and_skipped(tmp_path):
    for i in range(4):
        cv2.imwrite(str(tmp_path / f"{i:06d}.png"), np.full((20, 30, 3), 40 * i, np.uint8))
    (tmp_path / "000002.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(50))
    skipped: list[int] = []
    frames = list(iter_frames(tmp_path, skipped=skipped))
    assert [f.index for f in frames] == [0, 1, 3] and skipped == [2]


def test_frames_of_different_sizes_are_an_input_error_before_decoding(tmp_path):
    for i in range(5):
        size = (40, 30) if i != 3 else (20, 15)
        cv2.imwrite(str(tmp_path / f"{i:06d}.jpg"), np.zeros((size[1], size[0], 3), np.uint8))
    with pytest.raises(InconsistentInputError, match=r"000003\.jpg"):  # the odd frame named
        video_info(tmp_path)
