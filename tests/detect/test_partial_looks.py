"""Keyframes that look at part of the frame, the grid known ahead, the detector in a worker
thread, and fast videos analysed at a lower rate."""

from __future__ import annotations

import threading
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.core.records import Detection, Frame, RangedBox
from vid2sim.detect.frameloop import DetectAhead, fill_between, lookahead
from vid2sim.detect.pipeline import run_detect
from vid2sim.detect.schedule import (
    BAND,
    LOCAL,
    SWEEP,
    KeyframeGrid,
    KeyframeSchedule,
    ScheduleConfig,
)
from vid2sim.detect.tracking.tracker import LOST, TRACKED, Tracker
from vid2sim.detect.vehicles.windows import (
    Look,
    band_look,
    best_scales,
    full_look,
    local_look,
    net_scale,
    seen_by,
)

KITTI = (1242, 374)
NET = (416, 416)


# --------------------------------------------------------------------------- windows


def test_full_look_of_a_wide_frame_and_its_scales():
    look = full_look(*KITTI)
    assert look.windows[0] == (0, 0, 1242, 374) and len(look.windows) == 4
    assert look.centre == look.windows[3]
    # the full frame at 416/1242, the tiles (683 wide) at 416/683, the centre (374) at 416/374
    assert [round(look.scale(i, NET), 3) for i in range(4)] == [0.335, 0.609, 0.609, 1.112]
    assert full_look(640, 480).windows == ((0, 0, 640, 480),)  # 4:3: no tiles


def test_band_look_cuts_the_windows_but_keeps_their_scale():
    full = full_look(*KITTI)
    band = band_look(full, (133.3, 294.5))
    assert not band.sweep and band.windows[0] == full.windows[0]
    assert [w[1::2] for w in band.windows[1:]] == [(133, 295)] * 3
    assert band.centre == (434, 133, 808, 295)
    assert [band.scale(i, NET) for i in range(4)] == [full.scale(i, NET) for i in range(4)]
    # a band lower than MIN_BAND_ROWS_PX keeps only the full frame
    assert band_look(full, (100, 120)).windows == (full.windows[0],)


def test_seen_by_a_band_is_where_a_sweep_would_have_seen_as_well():
    full = full_look(*KITTI)
    band = band_look(full, (130, 300))
    boxes = np.array([[600, 170, 620, 190],    # small, centre, inside the band
                      [100, 20, 140, 50],      # small, far above the band: not seen
                      [100, 150, 300, 360],    # tall (210 px): the full frame suffices
                      [700, 140, 760, 320]])   # 180 px tall crossing the band's bottom
    seen = seen_by(boxes, band, full, NET, 24.0, KITTI)
    assert seen.tolist() == [True, False, True, True]
    assert seen_by(boxes, full, full, NET, 24.0, KITTI).all()  # a sweep sees everything


def test_local_look_sees_its_boxes_at_the_sweep_scale_and_nothing_else():
    full = full_look(*KITTI)
    boxes = np.array([[600.0, 170.0, 630.0, 195.0], [50.0, 200.0, 90.0, 235.0]])
    look = local_look(boxes, full, NET, KITTI)
    assert look.refine and len(look.windows) == 2
    # the centre car at the centre window's scale, the left one at the left tile's
    assert look.caps == pytest.approx((416 / 374, 416 / 683))
    for window, box in zip(look.windows, boxes, strict=True):
        assert window[0] <= box[0] and window[2] >= box[2]  # each crop holds its box
    assert seen_by(boxes, look, full, NET, 24.0, KITTI).all()
    other = np.array([[1000.0, 170.0, 1030.0, 195.0]])
    assert not seen_by(other, look, full, NET, 24.0, KITTI).any()


@settings(max_examples=60, deadline=None)
@given(x=st.floats(0, 1200), y=st.floats(0, 340), w=st.floats(4, 300), h=st.floats(4, 300))
def test_a_sweep_sees_every_box_and_best_scale_is_one_of_its_windows(x, y, w, h):
    full = full_look(*KITTI)
    box = np.array([[x, y, min(x + w, KITTI[0]), min(y + h, KITTI[1])]])
    assert seen_by(box, full, full, NET, 24.0, KITTI).all()
    best = best_scales(box, full, NET)[0]
    assert any(best == pytest.approx(net_scale(win, NET)) for win in full.windows)
    # a band about the box (at least MIN_BAND_ROWS_PX high) sees it too
    band = band_look(full, (box[0, 1] - 32, box[0, 3] + 32))
    assert seen_by(box, band, full, NET, 24.0, KITTI).all()


# --------------------------------------------------------------------------- tracker


def _car(x: float, score: float = 0.9, y: float = 150.0) -> Detection:
    return Detection((x, y, x + 60.0, y + 40.0), score, "car")


def test_a_track_the_detector_did_not_look_at_is_carried_not_missed():
    tracker = Tracker(image_size_px=(640, 360))
    for i in range(2):  # confirmed
        tracker.update(i, i / 10, [_car(100.0 + 2 * i), _car(400.0 + 2 * i)])
    left, right = sorted(t.track_id for t in tracker.tracks())

    def left_half(boxes):
        return boxes[:, 2] <= 320

    moved = np.array([406.0, 150.0, 466.0, 190.0])
    rows = tracker.update(2, 0.2, [], measured={right: moved}, seen=left_half)
    states = {t.track_id: t.state for t in tracker.tracks()}
    assert states == {left: LOST, right: TRACKED}  # missed where looked, carried elsewhere
    (row,) = [r for r in rows if r.track_id == right]
    assert (row.x1, row.x2) == (406.0, 466.0)  # its measured (flow) box


def test_a_young_track_outside_the_look_is_not_deleted_as_a_false_detection():
    tracker = Tracker(image_size_px=(640, 360))
    tracker.update(0, 0.0, [_car(400.0)])
    (tid,) = [t.track_id for t in tracker.tracks()]
    tracker.update(1, 0.1, [], seen=lambda boxes: np.zeros(len(boxes), bool))
    assert [t.track_id for t in tracker.tracks()] == [tid]  # alive, still tentative
    tracker.update(2, 0.2, [_car(404.0)])
    assert tracker.tracks()[0].confirmed
    # looked at and missed on the next frame instead: deleted (a false detection)
    other = Tracker(image_size_px=(640, 360))
    other.update(0, 0.0, [_car(400.0)])
    other.update(1, 0.1, [], seen=lambda boxes: np.ones(len(boxes), bool))
    assert other.tracks() == []


# --------------------------------------------------------------------------- schedule


def test_the_grid_depends_on_time_only_and_sweeps_on_its_own_cadence():
    grid = KeyframeGrid(ScheduleConfig(keyframe_s=0.3, sweep_s=0.9))
    plans = [grid.plan(i / 10) for i in range(12)]
    assert plans == [SWEEP, None, None, BAND, None, None, BAND, None, None, SWEEP, None, None]
    every = KeyframeGrid(ScheduleConfig(keyframe_s=0.3, sweep_s=0))  # every grid keyframe
    assert [every.plan(i / 10) for i in range(7)] == [SWEEP, None, None, SWEEP, None, None,
                                                       SWEEP]
    sparse = KeyframeGrid(ScheduleConfig(keyframe_s=0.3, sweep_s=0.9))
    assert [sparse.plan(i * 0.5) for i in range(4)] == [SWEEP] * 4  # sparse: all sweeps


def test_a_keyframe_the_tracks_ask_for_looks_at_them_only():
    keys = KeyframeSchedule(ScheduleConfig(keyframe_s=1.0, local_looks=True), 640)
    tracker = Tracker(image_size_px=(640, 360))
    assert keys.decide(0.0, keys.grid.plan(0.0)) == SWEEP
    tracker.update(0, 0.0, [_car(100.0), _car(400.0)])
    keys.after_keyframe(tracker, 0.0)
    assert keys.decide(0.1, keys.grid.plan(0.1)) == LOCAL  # the second look
    assert set(keys.focus) == {t.track_id for t in tracker.tracks()}
    keys.after_keyframe(tracker, 0.1)
    assert keys.decide(0.2, keys.grid.plan(0.2)) is None
    assert keys.reasons == {"first": 1, "new track": 1}


# --------------------------------------------------------------------------- ahead


class BlockDetector:
    """Finds the bright block of the synthetic clips (a stand-in for a net), in any thread."""

    def __init__(self):
        self.calls: list[int] = []
        self.threads: set[str] = set()
        self.lock = threading.Lock()

    def detect(self, image_bgr: np.ndarray) -> list[Detection]:
        with self.lock:
            self.calls.append(int(image_bgr[0, 0, 1]))  # the frame number is painted there
            self.threads.add(threading.current_thread().name)
        ys, xs = np.nonzero(image_bgr[:, :, 0] > 90)
        if len(xs) == 0:
            return []
        return [Detection((float(xs.min()), float(ys.min()), float(xs.max() + 1),
                           float(ys.max() + 1)), 0.9, "car")]


def test_lookahead_shows_each_frame_before_it_is_yielded():
    seen: list[int] = []
    frames = (Frame(i, i / 10, None) for i in range(6))
    for frame in lookahead(frames, 2, lambda f: seen.append(f.index)):
        assert seen[-1] == min(frame.index + 2, 5)
    assert seen == list(range(6))


def test_detect_ahead_hands_back_the_boxes_of_each_frame():
    det = BlockDetector()
    ahead = DetectAhead(det)
    images = {}
    for i in range(3):
        img = np.zeros((40, 60, 3), np.uint8)
        img[0, 0, 1] = i
        img[10:20, 5 + 10 * i:15 + 10 * i] = 200
        images[i] = img
        ahead.submit(i, img, SWEEP, None)
    for i in (0, 2):  # frame 1 never taken: dropped when frame 2 is
        kind, look, found = ahead.take(i)
        assert kind == SWEEP and look is None
        assert found == det.detect(images[i])
    assert ahead.take(1) is None
    ahead.close()
    assert any(name.startswith("vid2sim-detect") for name in det.threads)


def _block_clip(path: Path, fps: float, n: int) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (160, 96))
    for i in range(n):
        img = np.zeros((96, 160, 3), np.uint8)
        x = int(20 + 60 * i / n)
        img[40:70, x:x + 40] = 180
        writer.write(img)
    writer.release()
    return path


def test_the_worker_changes_nothing_in_the_rows(tmp_path):
    clip = _block_clip(tmp_path / "c.mp4", 10.0, 30)
    runs = [run_detect(clip, detector=BlockDetector(), progress=False,
                       schedule=ScheduleConfig(), ahead=ahead) for ahead in (False, True)]
    assert runs[0] == runs[1] and len(runs[0]) == 30


def test_a_30_fps_video_is_analysed_at_10_hz_with_rows_on_every_frame(tmp_path):
    clip = _block_clip(tmp_path / "c30.mp4", 30.0, 60)
    det = BlockDetector()
    decoded: list[int] = []
    stats: dict = {}
    rows = run_detect(clip, detector=det, progress=False, schedule=ScheduleConfig(),
                      on_frame=lambda f: decoded.append(f.index), stats=stats)
    assert decoded == list(range(0, 60, 3))  # every 3rd frame decoded
    assert stats["analysed"] == 20 and stats["frames"] == 60
    assert [r.frame for r in rows] == list(range(58))  # the last two follow no analysed frame
    # between two analysed frames the box is interpolated in time
    by_frame = {r.frame: r for r in rows}
    a, b, mid = by_frame[30], by_frame[33], by_frame[31]
    assert mid.x1 == pytest.approx(a.x1 + (b.x1 - a.x1) / 3, abs=1e-6)
    assert mid.t_s == pytest.approx(31 / 30, abs=2e-3)


def test_fill_between_interpolates_tracks_seen_on_both_sides_only():
    def box(frame, tid, x, rng=20.0):
        return RangedBox(frame, frame / 30, tid, "car", 0.8, x, 10.0, x + 20.0, 30.0,
                         range_m=rng, lateral_m=1.0, range_rate_mps=-3.0, range_std_m=1.0,
                         is_lead=tid == 1, lane=0)

    times = {i: i / 30 for i in range(7)}
    rows = [box(0, 1, 0.0), box(0, 2, 50.0), box(3, 1, 30.0, 17.0), box(3, 3, 90.0),
            box(6, 3, 96.0)]
    out = fill_between(rows, times, 3)
    assert [(r.frame, r.track_id) for r in out] == [
        (0, 1), (0, 2), (1, 1), (2, 1), (3, 1), (3, 3), (4, 3), (5, 3), (6, 3)]
    one = {r.frame: r for r in out if r.track_id == 1}
    assert one[1].x1 == pytest.approx(10.0) and one[2].range_m == pytest.approx(18.0)
    assert one[1].t_s == pytest.approx(1 / 30) and one[2].is_lead and one[2].lane == 0
    assert fill_between(rows, times, 1) is rows
    del times[4]  # a frame that did not decode gets no row
    assert [r.frame for r in fill_between(rows, times, 3) if r.track_id == 3] == [3, 5, 6]


def test_analysis_step_names_the_rate():
    cfg = ScheduleConfig()
    assert [cfg.analysis_step(f) for f in (10.0, 12.5, 15.0, 25.0, 30.0, 60.0)] == [1, 1, 2, 2,
                                                                                  3, 6]
    assert ScheduleConfig(analysis_hz=0).analysis_step(30.0) == 1
    assert Look(((0, 0, 10, 10),)).scale(0, NET) == pytest.approx(41.6)
