"""The lane track on observation sequences made from a known lateral motion."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.detect.lanes.lane_frames import FPS, W, observations
from vid2sim.core.records import LaneObservation
from vid2sim.detect.lanes.track import LaneTrackConfig, lane_track, track_lanes


def test_holding_the_lane_noise_and_outliers_are_filtered():
    n = 200
    truth = 0.25 + 0.15 * np.sin(np.arange(n) / FPS * 0.4)
    obs = observations(truth, noise_m=0.04, heading_noise=0.01, outliers=0.15, seed=1)
    for speed in (None, np.full(n, 12.0)):
        track = lane_track(obs, speed_mps=speed)
        err = track.ego_offset_m - truth
        assert np.sqrt(np.mean(err ** 2)) < 0.05
        assert track.lane_changes == []
        assert (track.lane == 0).all()
        assert np.median(track.lane_width_m) == pytest.approx(W, abs=0.05)
    raw = np.array([o.ego_offset_m for o in obs]) - truth
    assert np.sqrt(np.nanmean(raw ** 2)) > np.sqrt(np.mean(err ** 2))
    assert 0.5 < track.detection_rate <= 1.0


@pytest.mark.parametrize("direction", [1, -1])
def test_a_lane_change_is_one_change_at_the_crossing(direction):
    t = np.arange(0.0, 16.0, 1.0 / FPS)
    start, dur = 6.0, 3.0
    u = np.clip((t - start) / dur, 0.0, 1.0)
    truth = direction * W * u ** 3 * (10 - 15 * u + 6 * u * u)  # minimum-jerk change
    obs = observations(truth, noise_m=0.03, heading_noise=0.008, seed=2)
    track = lane_track(obs, speed_mps=np.full(len(t), 12.0))
    assert len(track.lane_changes) == 1
    change = track.lane_changes[0]
    assert (change.from_lane, change.to_lane) == (0, direction)
    assert change.t_s == pytest.approx(start + dur / 2.0, abs=0.25)  # mid-change = boundary
    assert change.as_tuple() == (change.t_s, 0, direction)
    assert track.lane[0] == 0 and track.lane[-1] == direction
    np.testing.assert_allclose(track.lateral_m, truth, atol=0.12)
    # Within its lane the offset never runs beyond the boundary by more than the hysteresis.
    assert np.all(np.abs(track.ego_offset_m) <= W / 2 + LaneTrackConfig().hysteresis_m + 0.05)


@settings(max_examples=25)
@given(offset=st.floats(-1.2, 1.2), width=st.floats(2.6, 4.0), n=st.integers(5, 60))
def test_noise_free_steady_offsets_are_reproduced(offset, width, n):
    obs = observations(np.full(n, offset), width_m=width)
    track = lane_track(obs)
    np.testing.assert_allclose(track.ego_offset_m, offset, atol=0.02)
    np.testing.assert_allclose(track.lane_width_m, width, atol=1e-6)
    assert track.lane_changes == [] and len(track) == n


def test_long_gaps_are_unknown_short_ones_bridged():
    n = 150
    missing = np.zeros(n, bool)
    missing[30:40] = True  # 1 s: bridged
    missing[80:130] = True  # 5 s: beyond max_gap_s in its middle
    obs = observations(np.full(n, 0.3), missing=missing)
    track = lane_track(obs)
    assert np.isfinite(track.ego_offset_m[30:40]).all()
    assert np.isnan(track.ego_offset_m[100:110]).all()
    assert np.isfinite(track.ego_offset_m[:30]).all()
    assert track.found[missing].sum() == 0


def test_no_lines_at_all():
    obs = [LaneObservation(frame=i, t_s=i / FPS) for i in range(20)]
    track = lane_track(obs)
    assert np.isnan(track.ego_offset_m).all() and track.detection_rate == 0.0
    assert track.lane_changes == []
    assert len(lane_track([])) == 0


def test_yaw_correction_before_tracking_turns_the_headings():
    obs = observations(np.full(30, 0.2))
    track = track_lanes(obs, yaw_correction_rad=0.01)
    assert track.observations[0].left.heading_rad == pytest.approx(
        obs[0].left.heading_rad + 0.01)
    assert np.nanmedian(track.heading_rad) == pytest.approx(0.01, abs=0.004)
