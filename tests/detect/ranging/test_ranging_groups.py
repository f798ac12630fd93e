"""The ranging run on groups of tracks gives bitwise what one whole-clip pass gives.

Scenes generated in code (a parked row standing on ground below the ego's road, a lead driving
ahead, a car passing), ranged once with every track a group of its own and once with all
tracks in one group, with and without the ego's trajectory.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.detect.ranging.test_ranging_standing import CAM, standing_boxes, straight_path
from vid2sim.detect.ranging import groups, range_tracks
from vid2sim.detect.ranging.groups import FitColumns, track_groups


def _scene():
    path = straight_path(10.0)
    boxes = []
    for i in range(4):  # parked on ground 0.3 m below the ego's road
        b, _ = standing_boxes(path, (35.0 + 9.0 * i, 8.5), track_id=i + 1, ground_m=-0.3,
                              t_span=(0.3 * i, 0.3 * i + 2.5), seed=i)
        boxes += b
    lead, _ = standing_boxes(path, (20.0, 0.0), track_id=7, along_mps=7.0, t_span=(0.0, 4.0),
                             seed=7)
    passing, _ = standing_boxes(path, (30.0, -3.5), track_id=9, along_mps=13.0,
                                t_span=(0.5, 3.0), seed=9)
    boxes = lead + boxes + passing  # not in track order: groups follow the track ids
    return sorted(boxes, key=lambda b: (b.frame, b.track_id)), path


def _everything(result) -> str:
    # repr of a float round-trips exactly: equal text is equal bits (NaN included)
    return repr((result.boxes, result.pitch_deg_estimated, result.horizon_y_px,
                 list(result.width_m_by_track.items()), list(result.ground_m_by_track.items()),
                 sorted(result.standing_tracks), [str(n) for n in result.warnings]))


@pytest.mark.parametrize("with_path", [False, True])
def test_groups_of_tracks_range_bitwise_as_one_pass(monkeypatch, with_path):
    boxes, path = _scene()
    options = {"ego_path": path} if with_path else {}
    monkeypatch.setattr(groups, "GROUP_BOXES", 10 ** 9)
    whole = range_tracks(boxes, CAM, **options)
    monkeypatch.setattr(groups, "GROUP_BOXES", 1)
    apart = range_tracks(boxes, CAM, **options)
    monkeypatch.setattr(groups, "GROUP_BOXES", 60)
    some = range_tracks(boxes, CAM, **options)
    assert len(whole.boxes) == len(boxes)
    assert whole.standing_tracks == (frozenset({1, 2, 3, 4}) if with_path else frozenset())
    assert _everything(apart) == _everything(whole)
    assert _everything(some) == _everything(whole)


@given(st.lists(st.integers(1, 40), min_size=0, max_size=30), st.integers(1, 100))
def test_track_groups_keep_tracks_whole_and_in_order(sizes, max_boxes):
    start = np.cumsum([0] + sizes)
    tracks = {10 + k: np.arange(start[k], start[k + 1])[::-1] for k in range(len(sizes))}
    found = track_groups(tracks, max_boxes)
    assert [t for g in found for t in g.tracks] == list(tracks)
    for g in found:
        assert g.index.size <= max_boxes or len(g.tracks) == 1
        for tid, pos in g.tracks.items():
            np.testing.assert_array_equal(g.index[pos], tracks[tid])
    if found:
        np.testing.assert_array_equal(np.concatenate([g.index for g in found]),
                                      np.concatenate(list(tracks.values())))


def test_fit_columns_put_fills_only_their_rows():
    cols = FitColumns.empty(5)

    class Part:
        range_m = np.array([10.0, 20.0])
        lateral_m = np.array([1.0, -1.0])
        valid = np.array([True, False])
        ground_ok = np.array([True, True])
        width_ok = np.array([False, True])

    cols.put(np.array([3, 1]), Part)
    np.testing.assert_array_equal(cols.range_m, [np.nan, 20.0, np.nan, 10.0, np.nan])
    np.testing.assert_array_equal(cols.valid, [False, False, False, True, False])
    np.testing.assert_array_equal(cols.width_ok, [False, True, False, False, False])
