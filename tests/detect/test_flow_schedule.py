"""Optical-flow carrying of boxes, the keyframe schedule, and the background decoder."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vid2sim.base.errors import InputError
from vid2sim.core.records import Detection, Frame
from vid2sim.detect.schedule import KeyframeSchedule, ScheduleConfig
from vid2sim.detect.tracking.flow import MedianFlow
from vid2sim.detect.tracking.tracker import Tracker
from vid2sim.detect.video import prefetch

W, H = 640, 360


def textured_scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A smooth grey background and a 120x80 px patch of random texture (the 'car')."""
    background = cv2.GaussianBlur(rng.integers(0, 255, (H, W), dtype=np.uint8), (31, 31), 0)
    patch = cv2.GaussianBlur(rng.integers(0, 255, (80, 120), dtype=np.uint8), (3, 3), 0)
    return background, patch


def paste(background: np.ndarray, patch: np.ndarray, cx: float, cy: float, scale: float
          ) -> tuple[np.ndarray, np.ndarray]:
    """The frame with the patch scaled about its centre and placed at (cx, cy), and its box."""
    ph, pw = patch.shape
    m = np.array([[scale, 0.0, cx - scale * pw / 2], [0.0, scale, cy - scale * ph / 2]])
    warped = cv2.warpAffine(patch, m, (W, H), flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(np.ones_like(patch), m, (W, H), flags=cv2.INTER_NEAREST)
    frame = np.where(mask > 0, warped, background)
    box = np.array([cx - scale * pw / 2, cy - scale * ph / 2, cx + scale * pw / 2,
                    cy + scale * ph / 2])
    return cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR), box


def test_median_flow_follows_a_shift_and_a_growth():
    rng = np.random.default_rng(1)
    background, patch = textured_scene(rng)
    first, box0 = paste(background, patch, 300.0, 180.0, 1.0)
    second, box1 = paste(background, patch, 306.0, 183.0, 1.08)  # moved and 8 % nearer
    flow = MedianFlow()
    flow.carry(first, np.zeros((0, 4)))
    moved, ok = flow.carry(second, box0[None])
    assert ok[0]
    assert moved[0] == pytest.approx(box1, abs=1.5)


def test_median_flow_prepared_ahead_in_another_thread_carries_the_same():
    # The grey images made ahead (as the decoding thread does) give the same carry as those
    # made in carry(); an image prepared for a frame that was never carried is dropped.
    import threading

    rng = np.random.default_rng(3)
    background, patch = textured_scene(rng)
    frames = [paste(background, patch, 300.0 + 4 * k, 180.0 + k, 1.0 + 0.03 * k)
              for k in range(4)]
    inline, ahead = MedianFlow(), MedianFlow()
    worker = threading.Thread(target=lambda: [ahead.prepare(k, f) for k, (f, _) in
                                              enumerate(frames)])
    worker.start()
    worker.join()
    assert sorted(ahead._ready) == [0, 1, 2, 3]
    inline.carry(frames[0][0], np.zeros((0, 4)))
    ahead.carry(frames[0][0], np.zeros((0, 4)), 0)
    for k in (1, 3):  # frame 2 is skipped: its prepared image goes with the next carry
        box = frames[k - 1][1][None]
        a, ok_a = inline.carry(frames[k][0], box)
        b, ok_b = ahead.carry(frames[k][0], box, k)
        assert ok_a[0] and ok_b[0]
        assert np.array_equal(a, b)
    assert ahead._ready == {}


def test_median_flow_refuses_a_box_without_texture_and_needs_a_previous_frame():
    rng = np.random.default_rng(2)
    background, patch = textured_scene(rng)
    first, box0 = paste(background, patch, 300.0, 180.0, 1.0)
    flat = np.array([20.0, 20.0, 60.0, 50.0])  # a blurred, featureless corner
    flow = MedianFlow()
    moved, ok = flow.carry(first, box0[None])  # no previous frame yet
    assert not ok.any() and moved[0] == pytest.approx(box0)
    smooth = np.full_like(first, 128)
    flow.carry(smooth, np.zeros((0, 4)))
    moved, ok = flow.carry(smooth, flat[None])
    assert not ok[0] and moved[0] == pytest.approx(flat)


def _car(x: float, score: float = 0.9) -> Detection:
    return Detection((x, 150.0, x + 60.0, 190.0), score, "car")


def test_schedule_runs_keyframes_by_time_and_a_second_look_at_new_tracks():
    keys = KeyframeSchedule(ScheduleConfig(keyframe_s=0.3, sweep_s=0.9, local_looks=True), W)
    tracker = Tracker(image_size_px=(W, H))
    picked = []
    for i in range(10):
        t = i / 10.0
        if keys.is_keyframe(t):
            picked.append(i)
            tracker.update(i, t, [_car(100.0 + 2 * i)])
            keys.after_keyframe(tracker, t)
        else:
            ids, boxes = tracker.shown_boxes()
            tracker.update(i, t, None, measured=dict(zip(ids, boxes, strict=True)))
            keys.after_carry(tracker, dict.fromkeys(ids, True))
    # frame 0 starts a track: frame 1 looks again; the grid every 0.3 s from frame 0 (a
    # keyframe the tracks asked for does not move it, so the grid is known ahead)
    assert picked == [0, 1, 3, 6, 9]
    assert keys.reasons == {"first": 1, "new track": 1, "interval": 2, "sweep": 1}
    # a full sweep on the first frame and every 0.9 s; the second look at the new track
    # alone; the grid keyframes between sweeps at the tracks
    assert keys.looks == {"sweep": 2, "local": 1, "band": 2}
    # sparse input (2 frames/s): every frame is a keyframe
    sparse = KeyframeSchedule(ScheduleConfig(keyframe_s=0.3), W)
    assert all(sparse.is_keyframe(i * 0.5) for i in range(5))
    # keyframe_s 0: the detector on every frame
    every = KeyframeSchedule(ScheduleConfig(keyframe_s=0.0), W)
    assert all(every.is_keyframe(i * 0.01) for i in range(5))


def test_schedule_asks_for_a_keyframe_when_flow_fails_on_a_confirmed_track():
    keys = KeyframeSchedule(ScheduleConfig(keyframe_s=1.0), W)
    tracker = Tracker(image_size_px=(W, H))
    for i in range(2):  # confirmed after two detections
        assert keys.is_keyframe(i / 10)
        tracker.update(i, i / 10, [_car(300.0)])
        keys.after_keyframe(tracker, i / 10)
    assert not keys.is_keyframe(0.2)
    ids, _ = tracker.shown_boxes()
    tracker.update(2, 0.2, None, measured={})
    keys.after_carry(tracker, dict.fromkeys(ids, False))
    assert keys.is_keyframe(0.3) and keys.reasons["flow failed"] == 1


def test_measured_boxes_are_rows_and_correct_the_filter_without_confirming():
    tracker = Tracker(image_size_px=(W, H))
    rows = tracker.update(0, 0.0, [_car(100.0)])
    (tid,) = [r.track_id for r in rows]
    box = np.array([110.0, 150.0, 170.0, 190.0])
    (row,) = tracker.update(1, 0.1, None, measured={tid: box})
    assert (row.x1, row.x2) == (110.0, 170.0)
    assert not tracker.tracks()[0].confirmed  # flow is no detection
    assert tracker.tracks()[0].kf.mean[0] > 130.0  # the filter moved towards the measurement


def test_weak_track_is_confirmed_by_three_detections_spanning_the_confirm_time():
    weak = [Detection((200.0, 150.0, 240.0, 180.0), 0.3, "car")]
    frames = [weak, weak, weak, [], []]  # found three times in a row, then gone
    for dt, expected in ((0.5, 1), (0.1, 0)):  # 2 frames/s: kept; 10 frames/s: 3 are too few
        tracker = Tracker(image_size_px=(W, H))
        rows = []
        for i, dets in enumerate(frames):
            rows += tracker.update(i, i * dt, dets)
        assert len({r.track_id for r in tracker.finalize(rows)}) == expected, dt
    # found on every frame up to the end of a short input (a folder of three keyframes)
    tracker = Tracker(image_size_px=(W, H))
    rows = []
    for i in range(3):
        rows += tracker.update(i, i * 0.1, weak)
    assert len(tracker.finalize(rows)) == 3


def test_prefetch_keeps_order_raises_errors_where_they_happen_and_stops_early():
    frames = [Frame(index=i, t_s=i / 10, image_bgr=None) for i in range(50)]
    assert [f.index for f in prefetch(iter(frames), depth=3)] == list(range(50))

    def broken():
        yield frames[0]
        raise InputError("clip.mp4", "cannot decode frame 1")

    got = []
    with pytest.raises(InputError, match="cannot decode frame 1"):
        for f in prefetch(broken()):
            got.append(f.index)
    assert got == [0]
    reader = prefetch(iter(frames), depth=2)
    assert next(reader).index == 0
    reader.close()  # must not hang with the reader blocked on a full buffer
