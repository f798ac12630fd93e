"""Lane markings measured on frames rendered from known ground-plane lines through the camera.

The frames (tests/detect/lane_frames.py) paint each pixel by what lies on the road at its
ground point, so the recovered offset [m], heading [rad], curvature [1/m] and kind have exact
answers.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tests.detect.lanes.lane_frames import DASHCAM, KITTI_CAM, Line, pitched, render
from vid2sim.core.records import MarkingKind
from vid2sim.detect.lanes.markings import LaneMarkingConfig, LaneMarkingDetector


def measure(camera, image, **config):
    return LaneMarkingDetector(camera, LaneMarkingConfig(**config)).measure(image, 7, 0.7)


@pytest.fixture(scope="module")
def straight_kitti():
    lines = [Line(1.6, period_m=12.0), Line(-1.9), Line(5.0)]
    return render(KITTI_CAM, lines, seed=1)


def test_straight_lane_offsets_kinds_width_and_further_lines(straight_kitti):
    obs = measure(KITTI_CAM, straight_kitti)
    assert obs.frame == 7 and obs.t_s == 0.7
    assert obs.found
    assert obs.left.offset_m == pytest.approx(1.6, abs=0.03)
    assert obs.right.offset_m == pytest.approx(-1.9, abs=0.02)
    assert obs.left.heading_rad == pytest.approx(0.0, abs=0.004)
    assert obs.right.heading_rad == pytest.approx(0.0, abs=0.004)
    assert obs.left.kind == MarkingKind.DASHED.value
    assert obs.right.kind == MarkingKind.SOLID.value
    assert obs.lane_width_m == pytest.approx(3.5, abs=0.04)
    # The camera is 0.15 m left of the lane's middle (-0.15 m between the lines' centres).
    assert obs.ego_offset_m == pytest.approx(0.15, abs=0.03)
    assert [ln.offset_m for ln in obs.lines_left] == [pytest.approx(5.0, abs=0.05)]
    assert obs.lines_right == ()
    assert 0.0 < obs.left.confidence <= 1.0 and obs.right.confidence > 0.8
    assert obs.cost_ms > 0


def test_heading_and_curvature_of_a_bending_lane():
    lines = [Line(1.5, 0.03, 0.004, period_m=9.0), Line(-1.8, 0.03, 0.004)]
    obs = measure(KITTI_CAM, render(KITTI_CAM, lines, seed=2))
    for got, want in ((obs.left, lines[0]), (obs.right, lines[1])):
        assert got.offset_m == pytest.approx(want.offset_m, abs=0.04)
        assert got.heading_rad == pytest.approx(0.03, abs=0.006)
        assert got.curvature_inv_m == pytest.approx(0.004, abs=0.0008)
        # The fitted clothoid follows the painted line where it was seen.
        x = np.linspace(got.x_near_m, got.x_far_m, 20)
        assert np.abs(got.y_at(x) - want.y_at(x)).max() < 0.08


def test_lane_change_geometry_the_camera_over_a_line():
    # Mid lane change: heading 0.05 rad, the dashed line 0.3 m left of the camera.
    lines = [Line(0.3, -0.05, period_m=12.0), Line(-3.2, -0.05), Line(3.8, -0.05)]
    obs = measure(DASHCAM, render(DASHCAM, lines, seed=3))
    assert obs.left.offset_m == pytest.approx(0.3, abs=0.05)
    assert obs.right.offset_m == pytest.approx(-3.2, abs=0.05)
    assert obs.left.heading_rad == pytest.approx(-0.05, abs=0.008)
    assert [ln.offset_m for ln in obs.lines_left] == [pytest.approx(3.8, abs=0.08)]


def test_offsets_survive_a_wrong_pitch():
    """A pitch error moves the horizon, which turns lines in the warped view but leaves
    their offsets beside the camera (x = 0) in place (module docstring)."""
    lines = [Line(1.7, period_m=12.0), Line(-1.8)]
    image = render(pitched(KITTI_CAM, 0.6), lines, seed=4)
    obs = measure(KITTI_CAM, image)
    assert obs.left.offset_m == pytest.approx(1.7, abs=0.06)
    assert obs.right.offset_m == pytest.approx(-1.8, abs=0.06)
    assert obs.lane_width_m == pytest.approx(3.5, abs=0.08)


def test_rough_surface_beyond_the_lane_is_the_road_edge_and_ends_the_road():
    # A kerb to gravel (a track bed) 1.6 m right of the camera; a painted line beyond it
    # (a rail) is not a line of the road.
    lines = [Line(1.4, period_m=9.0), Line(-3.0, width_m=0.08)]
    obs = measure(KITTI_CAM, render(KITTI_CAM, lines, edge_right_m=-1.6, seed=5))
    assert obs.right is not None and obs.right.kind == MarkingKind.ROAD_EDGE.value
    assert obs.right.offset_m == pytest.approx(-1.6, abs=0.06)
    assert obs.lines_right == ()
    assert obs.left.kind == MarkingKind.DASHED.value


def test_plain_asphalt_has_no_lane():
    obs = measure(KITTI_CAM, render(KITTI_CAM, [], seed=6))
    assert obs.left is None and obs.right is None
    assert np.isnan(obs.lane_width_m) and np.isnan(obs.ego_offset_m)


def test_frames_of_another_size_are_measured_with_the_scaled_camera(straight_kitti):
    half = cv2.resize(straight_kitti, (621, 187), interpolation=cv2.INTER_AREA)
    obs = measure(KITTI_CAM, half)
    assert obs.right.offset_m == pytest.approx(-1.9, abs=0.06)
    assert obs.left.offset_m == pytest.approx(1.6, abs=0.08)


def test_grey_frames_are_accepted(straight_kitti):
    grey = cv2.cvtColor(straight_kitti, cv2.COLOR_BGR2GRAY)
    obs = measure(KITTI_CAM, grey)
    assert obs.found and obs.lane_width_m == pytest.approx(3.5, abs=0.05)
