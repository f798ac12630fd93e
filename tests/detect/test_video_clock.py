"""The frames' clock is the container's, on the real KITTI drive re-encoded at test time:
H.265/HEVC, a variable frame rate (a 2x frame-rate jump mid-clip), a portrait phone-style
copy with a rotation flag."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from vid2sim.core.container import probe_container
from vid2sim.detect.video import iter_frames
from vid2sim.geo.oxts import read_kitti_stamps

TICKS = Fraction(1, 90000)


@pytest.fixture(scope="module")
def kitti(kitti_raw_dir) -> tuple[list[np.ndarray], np.ndarray]:
    """The drive's frames (cropped to even sizes for 4:2:0) and capture times [s from the
    first], from image_00_timestamps.txt."""
    import av

    with av.open(str(kitti_raw_dir / "video.mp4")) as c:
        frames = [f.to_ndarray(format="bgr24")[:374, :1242] for f in c.decode(video=0)]
    stamps = np.array(read_kitti_stamps(kitti_raw_dir / "image_00_timestamps.txt"))
    return frames, stamps - stamps[0]


def encode(path: Path, frames: list[np.ndarray], times_s, codec: str = "libx264",
           rotation_deg: int | None = None) -> Path:
    """Frames at the given presentation times (90 kHz clock) in an MP4."""
    import av

    with av.open(str(path), "w") as out:
        s = out.add_stream(codec, rate=10, options={"preset": "ultrafast", "crf": "12"})
        s.height, s.width = frames[0].shape[:2]
        s.pix_fmt = "yuv420p"
        s.time_base = TICKS
        s.codec_context.time_base = TICKS
        if rotation_deg is not None:
            s.set_display_rotation(rotation_deg)
        for img, t in zip(frames, times_s, strict=True):
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(img), format="bgr24")
            frame.pts, frame.time_base = round(t / TICKS), TICKS
            for p in s.encode(frame):
                out.mux(p)
        for p in s.encode():
            out.mux(p)
    return path


def _times(video: Path) -> np.ndarray:
    return np.array([f.t_s for f in iter_frames(video, every=1_000_000)])


def test_hevc_decodes_on_the_capture_clock(kitti, tmp_path):
    frames, stamps = kitti
    video = encode(tmp_path / "kitti_hevc.mp4", frames, stamps, codec="libx265")
    assert probe_container(video).video.codec == "hevc"
    t = _times(video)
    assert len(t) == len(stamps)
    assert np.abs(t - stamps).max() < 1e-3


def test_a_2x_frame_rate_jump_keeps_the_capture_times(kitti, tmp_path):
    """Second half at twice the rate (each frame followed by a copy halfway to the next):
    the original frames keep their KITTI capture times within 1 ms; an index / fps clock
    would be off by seconds."""
    frames, stamps = kitti
    half = len(frames) // 2
    out_frames, out_t, original = [], [], []
    for k, (img, t) in enumerate(zip(frames, stamps, strict=True)):
        original.append(len(out_t))
        out_frames.append(img)
        out_t.append(t)
        if k >= half and k + 1 < len(frames):
            out_frames.append(img)
            out_t.append((t + stamps[k + 1]) / 2)
    video = encode(tmp_path / "kitti_vfr.mp4", out_frames, out_t)
    info = probe_container(video).video
    assert info.variable_rate
    t = _times(video)
    assert len(t) == len(out_t)
    assert np.abs(t[original] - stamps).max() < 1e-3
    nominal = np.arange(len(t)) / info.nominal_fps
    assert np.abs(nominal[original] - stamps).max() > 1.0


def test_a_rotated_phone_clip_gives_the_upright_detections(kitti, tmp_path, model_dir):
    """Portrait pixels with a display rotation: the frames come upright, and the detector
    finds the same cars as on the upright copy."""
    from vid2sim.detect.vehicles.detector import load_detector

    frames, stamps = kitti[0][:6], kitti[1][:6]
    upright = encode(tmp_path / "upright.mp4", frames, stamps)
    portrait = [np.ascontiguousarray(np.rot90(f, k=-1)) for f in frames]  # stored turned right
    rotated = encode(tmp_path / "rotated.mp4", portrait, stamps, rotation_deg=90)
    info = probe_container(rotated).video
    assert info.rotation_deg == 90 and (info.width, info.height) == (1242, 374)
    detector = load_detector("yolox-nano", model_dir, small_object_mode=False)
    pairs = zip(iter_frames(upright), iter_frames(rotated), strict=True)
    n_boxes = 0
    for a, b in pairs:
        assert b.image_bgr.shape == a.image_bgr.shape
        assert np.abs(a.image_bgr.astype(int) - b.image_bgr.astype(int)).mean() < 2.0
        da, db = detector.detect(a.image_bgr), detector.detect(b.image_bgr)
        assert abs(len(da) - len(db)) <= 1
        for d in da:
            best = max((_iou(d.box_px, e.box_px) for e in db), default=0.0)
            assert best > 0.8 or d.score < 0.5
        n_boxes += len(da)
    assert n_boxes > 0


def _iou(a, b) -> float:
    x1, y1, x2, y2 = max(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), min(a[3], b[3])
    inter = max(0.0, x2 - x1) * max(0.0, y2 - y1)
    area = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / area if area > 0 else 0.0
