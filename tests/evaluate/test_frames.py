"""Sampled frames of a build without keyframes: which frames, what is drawn, the render
beside, and their section in the report."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tests.evaluate.conftest import CAMERA, make_scenario
from vid2sim.core.camera import Camera
from vid2sim.core.records import LaneTrack, RangedBox
from vid2sim.core.scenario import Event
from vid2sim.evaluate.frames import (
    FrameSampleConfig,
    draw_frame,
    gym_renders,
    lane_boundaries_px,
    pick_frames,
    sample_frame_figures,
    side_by_side,
)
from vid2sim.evaluate.report import render_report


def _lane_track(t: np.ndarray, width_m: float) -> LaneTrack:
    """The camera in the middle of a straight lane ``width_m`` wide at every time ``t``."""
    n = len(t)
    zero = np.zeros(n)
    return LaneTrack(frame=np.arange(n), t_s=t, found=np.ones(n, bool), ego_offset_raw_m=zero,
                     ego_offset_m=zero, offset_std_m=zero + 0.05, lateral_m=zero,
                     lane=np.zeros(n, int), lane_width_m=zero + width_m, heading_rad=zero,
                     curvature_inv_m=zero)


def test_pick_frames_spreads_and_adds_event_frames():
    ev = [Event("cut_in", "3", 2.04, 1, 0), Event("lane_change", "ego", 50.0, 0, -1)]
    picks = pick_frames(101, 10.0, ev, FrameSampleConfig(n_even=5))
    assert [k for k, _ in picks] == [0, 20, 25, 50, 75, 100]
    assert dict(picks)[20] == "cut_in 3 (+1 -> +0)"
    # an event beyond the clip lands on its last frame, with the even pick there
    assert dict(picks)[100] == "lane_change ego (+0 -> -1)"
    assert pick_frames(0, 10.0, ev) == []
    assert [k for k, _ in pick_frames(3, 10.0, [])] == [0, 1, 2]


def test_lane_boundaries_project_to_the_ground_lines():
    cam = Camera(image_width=1242, image_height=375, fx=721.5, fy=721.5, cx=609.6, cy=172.9,
                 height_m=1.65)
    lines = lane_boundaries_px(cam, _lane_track(np.arange(20) / 10.0, 3.5), 0.5)
    assert len(lines) == 2
    left, right = lines
    # pinhole on a flat road: u = cx - fx * y / x, v = cy + fy * h / x at x = 4 m
    assert left[0] == pytest.approx([609.6 - 721.5 * 1.75 / 4.0, 172.9 + 721.5 * 1.65 / 4.0],
                                    abs=0.5)
    assert right[0][0] == pytest.approx(609.6 + 721.5 * 1.75 / 4.0, abs=0.5)
    # both converge towards the horizon far ahead
    assert abs(left[-1][0] - right[-1][0]) < abs(left[0][0] - right[0][0]) / 5
    assert lane_boundaries_px(cam, None, 0.5) == []
    assert lane_boundaries_px(cam, _lane_track(np.arange(20) / 10.0, 3.5), 9.0) == []


def test_draw_frame_colours_by_lane_and_side_by_side_keeps_the_height():
    img = np.zeros((200, 300, 3), np.uint8)
    boxes = [RangedBox(frame=0, t_s=0.0, track_id=7, category="car", score=0.9, x1=20, y1=80,
                       x2=80, y2=140, range_m=12.0, lateral_m=0.0, range_rate_mps=0.0,
                       range_std_m=0.3, is_lead=True, lane=0),
             RangedBox(frame=0, t_s=0.0, track_id=8, category="car", score=0.9, x1=150, y1=80,
                       x2=200, y2=120, range_m=20.0, lateral_m=3.5, range_rate_mps=0.0,
                       range_std_m=0.3, is_lead=False, lane=1)]
    out = draw_frame(img, boxes, [np.array([[0.0, 199.0], [150.0, 100.0]])])
    assert img.max() == 0  # the input is untouched
    assert tuple(out[110, 20]) == (0, 140, 255)  # the ego lane's box edge, orange
    assert tuple(out[100, 150]) == (255, 120, 40)  # the left lane's, blue
    both = side_by_side(out, np.full((100, 250, 3), 255, np.uint8))
    assert both.shape == (200, 300 + 8 + 500, 3)


def test_render_and_figures_of_a_scenario(tmp_path):
    """The scenario's frames as a video; every picked frame becomes one side-by-side PNG."""
    sc = make_scenario()
    fps, n = 10.0, 30
    video = tmp_path / "clip.avi"
    wr = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), fps,
                         (CAMERA.image_width, CAMERA.image_height))
    for i in range(n):
        wr.write(np.full((CAMERA.image_height, CAMERA.image_width, 3), 60 + i, np.uint8))
    wr.release()
    renders = gym_renders(sc, [0.0, 1.5], fps)
    assert set(renders) == {0.0, 1.5}
    cfg = FrameSampleConfig()
    size, behind_px = cfg.render_size_px, cfg.render_behind_m * cfg.render_scale_px_per_m
    assert renders[0.0].shape == (round(size / 2 + behind_px), size, 3)
    # the ego (highway-env's green) sits in the middle, turned to head up: taller than wide
    ys, xs = np.nonzero(np.all(np.abs(renders[0.0].astype(int) - (0, 200, 50)) < 30, axis=2))
    assert abs(xs.mean() - size / 2) < 3 and abs(ys.mean() - size / 2) < 3
    assert np.ptp(ys) > 2 * np.ptp(xs)
    assert not np.array_equal(renders[0.0], renders[1.5])  # the scene moved
    sc.events = [Event("lane_change", "ego", 1.5, 0, 1)]
    figs = sample_frame_figures(tmp_path / "frames", video, CAMERA, [], None, sc, fps, n,
                                config=FrameSampleConfig(n_even=3))
    assert [p.name for _, p in figs] == ["frame_000000.png", "frame_000014.png",
                                         "frame_000015.png", "frame_000029.png"]
    assert "lane_change ego" in figs[2][0]
    img = cv2.imread(str(figs[0][1]))
    assert img.shape[0] == CAMERA.image_height
    assert img.shape[1] > CAMERA.image_width  # the render beside it
    html = render_report(scenario=sc, metrics=None,
                         frame_images=[(c, p, f"figures/frames/{p.name}") for c, p in figs])
    assert "Sampled frames" in html and 'href="figures/frames/frame_000015.png"' in html
    assert "Events" in html and "lane_change" in html


def test_sampled_frames_by_seeking_equal_the_streamed_ones(tmp_path):
    # A clip long enough that the picks lie more than read_frames' seek gap apart, coded with
    # predicted frames (mp4v): the frames found by seeking, timed from the detection stage's
    # table, give the same pictures as decoding the whole video up to the last pick.
    sc = make_scenario()
    n = 701
    fps = (n - 1) / sc.duration_s
    video = tmp_path / "long.mp4"
    wr = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), fps, (160, 64))
    assert wr.isOpened()
    for i in range(n):
        img = np.full((64, 160, 3), 40, np.uint8)
        cv2.putText(img, str(i), (5, 50), cv2.FONT_HERSHEY_SIMPLEX, 1.5, (255, 255, 255), 3)
        wr.write(img)
    wr.release()
    cfg = FrameSampleConfig(n_even=3)
    streamed = sample_frame_figures(tmp_path / "a", video, CAMERA, [], None, sc, fps, n,
                                    config=cfg)
    times = {i: i / fps for i in range(n)}
    sought = sample_frame_figures(tmp_path / "b", video, CAMERA, [], None, sc, fps, n,
                                  config=cfg, frame_times_s=times)
    assert [p.name for _, p in streamed] == ["frame_000000.png", "frame_000350.png",
                                             "frame_000700.png"]
    assert [c for c, _ in sought] == [c for c, _ in streamed]
    for (_, a), (_, b) in zip(streamed, sought, strict=True):
        assert np.array_equal(cv2.imread(str(a)), cv2.imread(str(b)))
    # a frame the table lacks (not streamed): the stage decodes the video as before
    partial = sample_frame_figures(tmp_path / "c", video, CAMERA, [], None, sc, fps, n,
                                   config=cfg, frame_times_s={0: 0.0})
    assert [c for c, _ in partial] == [c for c, _ in streamed]
