"""Rail vehicles: COCO's train and other tools' tram labels are the ``tram`` category; a tall
vehicle beyond the road edge is a tram on its own bed and never the lead, a tram in the
ego lane can be."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.core.camera import Camera
from vid2sim.core.records import (
    RAIL_CATEGORIES,
    VEHICLE_CATEGORIES,
    LaneBoundary,
    LaneObservation,
    LaneTrack,
    MarkingKind,
    TrackedBox,
)
from vid2sim.detect.assign import assign_lanes_and_lead
from vid2sim.detect.rail import RailConfig, beyond_edge, find_rail_tracks, relabel
from vid2sim.detect.ranging import RangingConfig
from vid2sim.detect.vehicles.detector import COCO_VEHICLES
from vid2sim.detect.vehicles.external import CATEGORY_ALIASES

CAM = Camera.default_for(1242, 375, hfov_deg=81.0)


def test_rail_labels_map_to_tram():
    assert COCO_VEHICLES[6] == "tram" and "tram" in VEHICLE_CATEGORIES
    assert RAIL_CATEGORIES == ("tram",)
    for name in ("train", "tram", "streetcar"):
        assert CATEGORY_ALIASES[name] == "tram"


def _box(track: int, frame: int, x_m: float, y_m: float, height_m: float, width_m: float,
         category: str) -> TrackedBox:
    """The box of a vehicle whose rear centre stands on the flat road at (x, y) [m]."""
    px, _ = CAM.project(np.array([[x_m, y_m, 0.0]]))
    u, v = float(px[0, 0]), float(px[0, 1])
    half = width_m * CAM.fx / x_m / 2.0
    h = height_m * CAM.fy / x_m
    return TrackedBox(frame, 0.1 * frame, track, category, 0.6, u - half, v - h, u + half, v)


def _lanes(n_frames: int) -> LaneTrack:
    """A lane track whose right boundary is a kerb 1.5 m right of the camera."""
    edge = LaneBoundary(-1.5, 0.0, 0.0, MarkingKind.ROAD_EDGE.value, 0.9)
    line = LaneBoundary(1.5, 0.0, 0.0, MarkingKind.DASHED.value, 0.9)
    obs = [LaneObservation(k, 0.1 * k, left=line, right=edge, lane_width_m=3.0,
                           ego_offset_m=0.0) for k in range(n_frames)]
    z = np.zeros(n_frames)
    return LaneTrack(np.arange(n_frames), 0.1 * np.arange(n_frames), np.ones(n_frames, bool),
                     z, z, z, z, z.astype(int), np.full(n_frames, 3.0), z, z,
                     left_kind=[MarkingKind.DASHED.value] * n_frames,
                     right_kind=[MarkingKind.ROAD_EDGE.value] * n_frames,
                     observations=obs)


def test_tall_vehicle_beyond_the_kerb_is_a_tram_on_its_own_bed():
    n = 10
    boxes = []
    for k in range(n):
        boxes.append(_box(1, k, 60.0 - k, -5.5, 3.4, 2.6, "car"))  # tram beyond the kerb
        boxes.append(_box(2, k, 30.0, 0.0, 1.5, 1.8, "car"))  # a car ahead in the lane
        boxes.append(_box(3, k, 40.0, -5.5, 1.5, 1.8, "car"))  # a car beyond: not tall
        boxes.append(_box(4, k, 45.0, 0.2, 3.2, 2.55, "bus"))  # a bus in the lane
    rail = find_rail_tracks(boxes, _lanes(n), CAM)
    assert rail.trams == {1} and rail.relabelled == {1} and rail.own_bed == {1}
    assert {b.category for b in relabel(boxes, rail.relabelled) if b.track_id == 1} == {"tram"}


def test_detector_tram_in_the_lane_is_not_on_its_own_bed():
    boxes = [_box(7, k, 40.0, 0.0, 3.4, 2.6, "tram") for k in range(8)]
    rail = find_rail_tracks(boxes, _lanes(8), CAM)
    assert rail.trams == {7} and not rail.own_bed and not rail.relabelled


def test_a_tram_on_its_own_bed_is_never_the_lead():
    # a tram 30 m ahead in the ego corridor and a car 50 m ahead: the tram leads unless it
    # is marked as running on its own bed
    boxes = [_box(1, 0, 30.0, 0.0, 3.4, 2.6, "tram"), _box(2, 0, 50.0, 0.0, 1.5, 1.8, "car")]
    rng, lat = np.array([30.0, 50.0]), np.array([0.0, 0.0])
    _, lead, _ = assign_lanes_and_lead(boxes, rng, lat, RangingConfig())
    assert lead.tolist() == [True, False]
    _, lead, _ = assign_lanes_and_lead(boxes, rng, lat, RangingConfig(),
                                       never_lead=np.array([True, False]))
    assert lead.tolist() == [False, True]


@settings(max_examples=80, deadline=None)
@given(x=st.floats(1.0, 200.0), y=st.floats(-20.0, 20.0))
def test_beyond_edge_matches_the_edges(x, y):
    right = LaneBoundary(-1.5, 0.0, 0.0, MarkingKind.ROAD_EDGE.value)
    left = LaneBoundary(4.5, 0.0, 0.0, MarkingKind.ROAD_EDGE.value)
    cfg = RailConfig()
    got = beyond_edge(x, y, (right, left), cfg)
    expected = -1 if y < -1.5 - cfg.beyond_edge_m else (1 if y > 4.5 + cfg.beyond_edge_m else 0)
    assert got == expected
    assert beyond_edge(x, y, (None, None), cfg) == 0


@pytest.mark.parametrize("category", ["tram"])
def test_tram_has_its_own_priors(category):
    prior = RangingConfig().priors[category]
    assert 2.3 <= prior.width_m <= 2.65
