"""The renderer draws vehicles where the camera model says they are."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vid2sim.core.records import TrackedBox
from vid2sim.detect.ranging import range_tracks
from vid2sim.samples.demo_sample import demo_camera
from vid2sim.samples.render import DrawnVehicle as VehicleState
from vid2sim.samples.render import RoadGeometry, SceneRenderer, _clip_near


def _straight_road(length_m: float = 300.0) -> RoadGeometry:
    s = np.arange(0.0, length_m + 0.5, 0.5)
    xy = np.column_stack((s - 20.0, np.zeros_like(s)))
    normal = np.tile([0.0, 1.0], (len(s), 1))
    return RoadGeometry(s_m=s, xy_m=xy, left_normal=normal, width_m=7.0, lane_width_m=3.5)


@pytest.fixture(scope="module")
def renderer() -> SceneRenderer:
    return SceneRenderer(demo_camera(960, 540), _straight_road())


def _mask_box(img: np.ndarray, empty: np.ndarray) -> tuple[float, float, float, float]:
    diff = np.abs(img.astype(int) - empty.astype(int)).max(axis=2) > 25
    ys, xs = np.nonzero(diff)
    return float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max())


@pytest.mark.parametrize(("x_m", "y_m", "yaw_rad", "style", "dims"), [
    (14.0, 0.0, 0.0, "car", (4.5, 1.8, 1.5)),
    (25.0, 3.5, math.pi, "car", (4.4, 1.8, 1.5)),
    (40.0, -1.5, 0.15, "car", (4.6, 1.85, 1.45)),
    (18.0, 2.0, 0.0, "van", (5.0, 1.95, 2.1)),
])
def test_truth_box_is_the_drawn_outline_inside_the_3d_box(renderer, x_m, y_m, yaw_rad, style,
                                                          dims):
    """Ego at the ENU origin heading east, so ENU = vehicle frame. The reported truth box is
    the box of the pixels drawn for the vehicle (tyres, body, cabin: what an annotator and a
    detector see) within a pixel, and it lies inside the camera's projection of the
    vehicle's 3D box, whose bottom edge it clears where the rear tyres touch the road ahead
    of the rear face."""
    cam = renderer.camera
    length, width, height = dims
    v = VehicleState("v", x_m, y_m, yaw_rad, length, width, height, (40, 40, 170), style)
    empty, _ = renderer.render((0.0, 0.0), 0.0, 20.0, [], draw_shadows=False)
    img, views = renderer.render((0.0, 0.0), 0.0, 20.0, [v], draw_shadows=False)
    cuboid = np.array(cam.project_box(np.array([x_m, y_m]), length, width, height, yaw_rad))
    drawn = np.array(_mask_box(img, empty))
    box = np.array(views[0].box_px)
    assert np.allclose(box, drawn, atol=1.5), (box, drawn)
    assert (box[:2] >= cuboid[:2] - 0.5).all() and (box[2:] <= cuboid[2:] + 0.5).all()
    assert box[3] < cuboid[3] - 0.1  # the tyres' contact, not the box's rear bottom edge
    assert views[0].visible_fraction > 0.97
    assert views[0].in_image_fraction > 0.99


def test_occluded_vehicle_reports_low_visibility(renderer):
    near = VehicleState("near", 10.0, -1.75, 0.0, 4.5, 1.8, 1.5, (40, 40, 170))
    far = VehicleState("far", 30.0, -1.75, 0.0, 4.5, 1.8, 1.5, (175, 120, 40))
    _, views = renderer.render((0.0, -1.75), 0.0, 20.0, [far, near])
    by_id = {v.id: v for v in views}
    assert by_id["near"].visible_fraction > 0.97
    assert by_id["far"].visible_fraction < 0.2
    assert by_id["far"].range_m == pytest.approx(30.0 - 2.25)


def test_vehicle_beside_the_camera_is_clipped_not_smeared(renderer):
    """A car overtaking alongside has corners behind the camera: it is near-clipped, drawn at
    the image's left edge, and its box is truncated there."""
    v = VehicleState("side", 1.0, 3.5, 0.0, 4.6, 1.85, 1.45, (175, 120, 40))
    _img, views = renderer.render((0.0, 0.0), 0.0, 20.0, [v])
    box = views[0].box_px
    assert box is not None and box[0] == 0.0
    assert box[2] < renderer.camera.cx
    assert views[0].in_image_fraction < 1.0


def test_vehicle_behind_is_not_drawn(renderer):
    v = VehicleState("behind", -12.0, 0.0, 0.0, 4.5, 1.8, 1.5, (40, 40, 170))
    empty, _ = renderer.render((0.0, 0.0), 0.0, 20.0, [])
    img, views = renderer.render((0.0, 0.0), 0.0, 20.0, [v])
    assert views[0].box_px is None
    assert np.array_equal(img, empty)


def test_near_clip_keeps_the_part_in_front():
    quad = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 2.0], [0.0, 0.0, 2.0]])
    clipped = _clip_near(quad, 0.5)
    assert (clipped[:, 2] >= 0.5 - 1e-12).all()
    assert len(clipped) == 4
    assert clipped[:, 2].min() == pytest.approx(0.5)


def test_cuboid_truth_would_hide_that_the_outline_ranging_is_right(renderer):
    """The renderer draws a car (its own model: tyres 0.5 m inside the rear face, body above
    its clearance, a raked cabin), independent of the ranging's outline model. A lead closing
    from 16 m to 6 m: ranged from the drawn outline's boxes the outline model is right within
    a few per cent; ranged from the cuboid boxes the demo's truth used to carry (the 3D box's
    projection) it reads short by the tyres' offset, the error the old demo reported against
    the correct physics."""
    cam = renderer.camera
    length, width, height = 4.5, 1.8, 1.5
    drawn, cuboid, truth = [], [], []
    for k in range(41):
        rear_m = 16.0 - 0.25 * k
        x = rear_m + length / 2.0
        v = VehicleState("lead", x, 0.0, 0.0, length, width, height, (40, 40, 170), "car")
        _, views = renderer.render((0.0, 0.0), 0.0, 20.0, [v], draw_shadows=False)
        t = k / 10.0
        drawn.append(TrackedBox(k, t, 1, "car", 0.9, *views[0].box_px))
        cuboid.append(TrackedBox(k, t, 1, "car", 0.9,
                                 *cam.project_box(np.array([x, 0.0]), length, width, height,
                                                  0.0)))
        truth.append(rear_m)
    truth = np.array(truth)

    def bias(boxes):
        r = np.array([b.range_m for b in range_tracks(boxes, cam).boxes])
        return float(np.median((r - truth) / truth))

    assert abs(bias(drawn)) < 0.03
    assert bias(cuboid) < bias(drawn) - 0.03
