"""Standing vehicles ranged from the ego's own motion, the ground under each car, and the scale
a track carries when its bottom leaves the image.

Ground truth is generated in code: vehicles at known places in the world, on ground of a known
height, seen from a known ego path (the outline's hull, :func:`vid2sim.core.outline.outline_boxes`,
with pixel noise); every formula is checked against its known answer.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vid2sim.core.camera import Camera
from vid2sim.core.outline import CLASS_SHAPES, outline_boxes, shape_matrix
from vid2sim.core.records import TrackedBox
from vid2sim.detect.ranging import EgoPath, RangingConfig, range_tracks, standing_range_rate
from vid2sim.detect.ranging.parallax import (
    StandingFit,
    fit_standing_track,
    place_standing,
)
from vid2sim.detect.ranging.scalefilter import RangeMeasurements, filter_range
from vid2sim.detect.ranging.surface import (
    StandingTracks,
    cross_slopes,
    fit_cross_slope,
    scale_sigmas,
    standing_verdict,
    track_grounds,
)

CAM = Camera(image_width=1242, image_height=375, fx=721.5, fy=721.5, cx=609.6, cy=172.9,
             height_m=1.65)
W, H, L = 1.75, 1.5, 4.4
DT = 0.1


def straight_path(speed_mps: float = 10.0, duration_s: float = 12.0, yaw_rate: float = 0.0,
                  noise_m: float | None = 0.02) -> EgoPath:
    """An ego driving east at a constant speed (turning at ``yaw_rate``), sampled at 10 Hz."""
    t = np.arange(0.0, duration_s + 1e-9, DT)
    h = yaw_rate * t
    if yaw_rate:
        x = speed_mps / yaw_rate * np.sin(h)
        y = speed_mps / yaw_rate * (1 - np.cos(h))
    else:
        x, y = speed_mps * t, np.zeros_like(t)
    return EgoPath(t, x, y, h, noise_m)


def standing_boxes(path: EgoPath, world_rear_xy: tuple[float, float], *, track_id: int = 1,
                   ground_m: float = 0.0, t_span: tuple[float, float] = (0.0, 4.0),
                   noise_px: float = 0.5, seed: int = 0, camera: Camera = CAM,
                   size: tuple[float, float, float] = (W, H, L), along_mps: float = 0.0
                   ) -> tuple[list[TrackedBox], np.ndarray]:
    """Boxes of a car standing (or moving along the x axis at ``along_mps``) with its rear at
    ``world_rear_xy`` in the world frame (the ego's start frame), aligned with the x axis, on
    ground ``ground_m`` above the ego's road; and its true rear range per box."""
    rng = np.random.default_rng(seed)
    w, h, length = size
    boxes, truth = [], []
    for k, t in enumerate(path.t_s):
        if not t_span[0] - 1e-9 <= t <= t_span[1] + 1e-9:
            continue
        ex, ey, eh = (float(np.interp(t, path.t_s, a)) for a in (path.x_m, path.y_m,
                                                                  path.heading_rad))
        cx, cy = world_rear_xy[0] + along_mps * t + length / 2 - ex, world_rear_xy[1] - ey
        c, s = math.cos(eh), math.sin(eh)
        fx, fy = c * cx + s * cy, -s * cx + c * cy
        box = outline_boxes(camera, np.array([fx - length / 2]), np.array([fy]), np.array([w]),
                            np.array([h]), np.array([length]), shape_matrix([CLASS_SHAPES["car"]]),
                            -eh, z_m=ground_m)[0]
        if not np.all(np.isfinite(box)) or box[0] < 10 or box[2] > camera.image_width - 11:
            continue
        b = box + rng.normal(0, noise_px, 4)
        b[3] = min(b[3], camera.image_height - 1)
        boxes.append(TrackedBox(k, round(float(t), 6), track_id, "car", 0.9, *b))
        truth.append(fx - length / 2)
    return boxes, np.array(truth)


# --------------------------------------------------------------------------- formulas


def test_relative_poses_known_answer():
    path = straight_path(10.0)
    p = path.relative_poses(np.array([1.0, 3.0]), 2.0)
    assert np.allclose(p, [[-10.0, 0.0, 0.0], [10.0, 0.0, 0.0]], atol=1e-9)
    # a ranging frame turned 1 deg left of the travel: the travel lies 1 deg left in it
    yawed = EgoPath(path.t_s, path.x_m, path.y_m, path.heading_rad, 0.02, math.radians(1.0))
    q = yawed.relative_poses(np.array([3.0]), 2.0)[0]
    assert q[0] == pytest.approx(10 * math.cos(math.radians(1)))
    assert q[1] == pytest.approx(10 * math.sin(math.radians(1))) and q[2] == 0.0
    v, w = straight_path(8.0, yaw_rate=0.1).speed_yaw_rate(np.array([5.0]))
    assert v[0] == pytest.approx(8.0, rel=1e-3) and w[0] == pytest.approx(0.1, rel=1e-6)


def test_standing_range_rate_known_answer():
    # a point 10 m to the left of an ego at 12 m/s turning left at 0.05 rad/s closes in at
    # 12 - 0.05 * 10 = 11.5 m/s
    assert standing_range_rate(20.0, 10.0, 12.0, 0.05) == pytest.approx(-11.5)
    assert np.allclose(standing_range_rate(np.ones(2), np.zeros(2), np.full(2, 7.0), 0.2), -7.0)


@given(st.floats(-3, 3), st.floats(-0.3, 0.3), st.floats(5, 60), st.floats(-12, 12),
       st.floats(3, 6))
def test_place_standing_keeps_one_place_in_the_world(dx, dpsi, x0, y0, length):
    # Whatever the ego's pose, the standing car's footprint centre put back into the
    # reference frame is where it was.
    theta = np.array([x0, y0, W, H, length, 0.0])
    poses = np.array([[dx, 0.5 * dx, dpsi]])
    rng, lat, yaw = place_standing(theta, poses)
    cx, cy = rng[0] + length / 2, lat[0]
    c, s = math.cos(dpsi), math.sin(dpsi)
    assert c * cx - s * cy + dx == pytest.approx(x0 + length / 2, abs=1e-9)
    assert s * cx + c * cy + 0.5 * dx == pytest.approx(y0, abs=1e-9)
    assert yaw[0] == pytest.approx(-dpsi)


def _fit(boxes: list[TrackedBox], path: EgoPath, start_range: float, start_lat: float,
         size_std: tuple[float, float, float] = (0.12, 0.12, 0.45)) -> StandingFit:
    obs = np.array([[b.x1, b.y1, b.x2, b.y2] for b in boxes])
    sig = np.full(obs.shape, 1.0)
    use = np.ones(obs.shape, dtype=bool)
    t = np.array([b.t_s for b in boxes])
    poses = path.relative_poses(t, float(t[len(t) // 2]))
    outline = shape_matrix([CLASS_SHAPES["car"]] * len(boxes))
    return fit_standing_track(CAM, obs, sig, use, outline, poses,
                              np.array([start_range, start_lat, W, H, L, 0.0]),
                              np.array([W, H, L, 0.0]), np.array([*size_std, 0.4]))


def test_standing_fit_measures_range_and_the_ground_under_it():
    # A car parked 8.5 m to the left on ground 0.35 m below the ego's road (the parked row of
    # KITTI raw 0001): the fit recovers its range to 1 % and its ground to 3 cm.
    path = straight_path(10.0)
    boxes, truth = standing_boxes(path, (40.0, 8.5), ground_m=-0.35, t_span=(0.0, 3.0))
    ref = len(boxes) // 2
    fit = _fit(boxes, path, truth[ref] * 0.85, 7.5)
    assert fit.converged and fit.chi2_per_dof < 2.0
    assert np.max(np.abs(fit.range_m - truth) / truth) < 0.01
    assert fit.ground_m == pytest.approx(-0.35, abs=0.03)


def test_moving_car_fits_only_at_another_scale():
    # A car driving away along the axis at 5 m/s ahead of a 10 m/s ego fits as a standing
    # one of twice its size (k = v / (v - u) = 2): the scale test says it moves.
    path = straight_path(10.0)
    cfg = RangingConfig()
    boxes, truth = standing_boxes(path, (25.0, 0.2), along_mps=5.0, t_span=(0.0, 3.0))
    ref = len(boxes) // 2
    pm, ps = np.array([W, H, L, 0.0]), np.array([0.12, 0.12, 0.45, 0.4])
    fit = _fit(boxes, path, truth[ref], 0.2)
    free = _fit(boxes, path, truth[ref], 0.2, size_std=(1.2, 1.2, 4.5))
    assert scale_sigmas(free, pm, ps, CAM.height_m, 0.4) > cfg.standing_scale_sigmas
    assert standing_verdict(fit, free, pm, ps, CAM.height_m, 0.4, cfg) is not None
    still, _ = standing_boxes(path, (25.0, 0.2), t_span=(0.0, 3.0))
    fit = _fit(still, path, truth[ref], 0.2)
    free = _fit(still, path, truth[ref], 0.2, size_std=(1.2, 1.2, 4.5))
    assert scale_sigmas(free, pm, ps, CAM.height_m, 0.4) < 1.5
    assert standing_verdict(fit, free, pm, ps, CAM.height_m, 0.4, cfg) is None


def test_track_grounds_carry_the_neighbours_surface():
    cfg = RangingConfig()
    fits = {t: StandingFit(np.array([20, 8.5, W, H, L, g]), np.diag([1e-4] * 6), 1.0,
                           np.zeros(1), np.zeros(1), True) for t, g in ((1, -0.30), (2, -0.40))}
    grounds = track_grounds(StandingTracks(fits), {1: 8.5, 2: 8.7, 3: 9.0, 4: 0.0}, cfg)
    assert grounds[1].height_m == -0.30 and grounds[1].source == "standing fit"
    # the ego plane's spread 9 m to the side as the prior, updated by the two neighbours'
    # mean (-0.35 m), spread by their scatter (0.05 m) and the mean's error (0.03 / sqrt 2)
    prior = math.hypot(0.10, 0.03 * (9.0 - 1.8))
    spread = math.hypot(0.05, 0.03 / math.sqrt(2))
    expect = -0.35 / spread ** 2 / (1 / prior ** 2 + 1 / spread ** 2)
    assert grounds[3].source == "standing neighbours"
    assert grounds[3].height_m == pytest.approx(expect)
    assert grounds[3].std_m == pytest.approx((1 / prior ** 2 + 1 / spread ** 2) ** -0.5)
    assert grounds[4].height_m == 0.0 and grounds[4].source == "ego plane"
    # a vehicle in the ego's lane stands on the lane the markings measure, whatever stands
    # beside it
    fits[5] = StandingFit(np.array([45, -1.2, W, H, L, 0.4]), np.diag([1e-2] * 6), 1.0,
                          np.zeros(1), np.zeros(1), True)
    lead = track_grounds(StandingTracks(fits), {5: -1.2, 6: 0.1}, cfg)[6]
    assert lead.height_m == 0.0 and lead.source == "ego plane"


def _standing(lateral_m: float, ground_m: float, std_m: float = 0.02) -> StandingFit:
    return StandingFit(np.array([25.0, lateral_m, W, H, L, ground_m]),
                       np.diag([1e-4] * 5 + [std_m ** 2]), 1.0, np.zeros(1), np.zeros(1), True)


def test_cross_slope_of_a_plane_through_the_ego_lane_with_a_hidden_bottom():
    cfg = RangingConfig()
    y = np.array([7.6, 8.0, 8.4, 8.8, 9.2, 8.6])
    g = -0.04 * y
    g[-1] += 0.6  # a car whose bottom a hedge hides: its ground reads 0.6 m high
    c = fit_cross_slope(y, g, np.full(y.size, 0.02), cfg)
    assert c.slope == pytest.approx(-0.04, abs=0.002)
    mean, spread = c.at(-5.0)
    assert mean == pytest.approx(0.20, abs=0.01)
    assert spread >= cfg.surface_floor_std_m
    assert fit_cross_slope(y[:2], g[:2], np.full(2, 0.02), cfg) is None


@given(st.floats(-0.08, 0.08), st.lists(st.floats(2.0, 6.0), min_size=3, max_size=8))
def test_cross_slope_recovers_any_plane(slope, offsets):
    y = 1.8 + np.array(offsets)
    c = fit_cross_slope(y, slope * y, np.full(y.size, 0.02), RangingConfig())
    assert c.slope == pytest.approx(slope, abs=1e-4)


def test_cross_slope_from_the_surface_next_to_the_ego_lane():
    cfg = RangingConfig()
    row = [(y, -0.04 * y, 0.02) for y in (8.0, 8.5, 9.0)]
    park = [(y, 0.3, 0.02) for y in (18.0, 19.0, 20.0)]  # beyond a hedge: not the road
    slopes = cross_slopes(row + park, cfg)
    assert slopes[1].slope == pytest.approx(-0.04, abs=1e-3) and slopes[1].n == 3
    # no standing vehicle on the right: the same plane (no crown is seen, none assumed)
    assert slopes[-1] is slopes[1]
    # a crown: each side its own fall
    right = [(y, 0.03 * y, 0.02) for y in (-6.0, -6.5, -7.0)]
    slopes = cross_slopes(row + right, cfg)
    assert slopes[-1].slope == pytest.approx(0.03, abs=1e-3)


def test_a_moving_vehicle_far_from_any_standing_one_takes_the_cross_slope():
    cfg = RangingConfig()
    fits = {t: _standing(y, -0.04 * y) for t, y in ((1, 8.0), (2, 8.5), (3, 9.0))}
    lateral = {1: 8.0, 2: 8.5, 3: 9.0, 4: -5.0, 5: 0.5}
    grounds = track_grounds(StandingTracks(fits), lateral, cfg)
    assert grounds[4].source == "road cross slope"
    slope = cross_slopes([(y, -0.04 * y, 0.02) for y in (8.0, 8.5, 9.0)], cfg)[-1]
    mean, spread = slope.at(-5.0)
    prior = math.hypot(cfg.road_height_std_m, cfg.road_height_std_per_lateral_m * (5.0 - 1.8))
    info = 1 / prior ** 2 + 1 / spread ** 2
    assert grounds[4].height_m == pytest.approx(mean / spread ** 2 / info)
    assert 0.1 < grounds[4].height_m < 0.2
    assert grounds[4].std_m == pytest.approx(info ** -0.5)
    # in the ego's lane the markings' plane, whatever the slope beside it
    assert grounds[5].height_m == 0.0 and grounds[5].source == "ego plane"


def test_filter_takes_the_ego_speed_as_the_rate_of_a_standing_vehicle():
    # One absolute range, then only the rate a standing vehicle has: the filter's range
    # follows the ego's motion exactly.
    n = 30
    t = np.arange(n) * DT
    nan = np.full(n, np.nan)
    abs_m = nan.copy()
    abs_m[0] = 30.0
    m = RangeMeasurements(t, abs_m, np.full(n, 0.01), nan, nan, np.full(n, 30.0), nan, nan,
                          nan, nan, 30.0, math.log(W), 0.01, rate_mps=np.full(n, -10.0),
                          rate_var=np.full(n, 0.01))
    fr = filter_range(m, (0.05,), 8.0)[0]
    assert np.allclose(fr.range_m, 30.0 - 10.0 * t, atol=0.05)
    assert np.allclose(fr.range_rate_mps, -10.0, atol=0.05)


# --------------------------------------------------------------------------- whole tracks


def _parked_row(path: EgoPath, ground_m: float, n: int = 4) -> tuple[list[TrackedBox], dict]:
    boxes, truth = [], {}
    for i in range(n):
        x0, t0 = 35.0 + 9.0 * i, 0.3 * i
        b, tr = standing_boxes(path, (x0, 8.5 + 0.2 * (i % 2)), track_id=i + 1,
                               ground_m=ground_m, t_span=(t0, t0 + 2.5), seed=i)
        boxes += b
        truth.update({(bb.frame, bb.track_id): r for bb, r in zip(b, tr, strict=True)})
    return boxes, truth


def test_parked_row_below_the_road_ranged_from_the_ego_motion():
    # A parked row on ground 0.35 m below the ego's road: from its boxes alone the ranging
    # reads it near (the ground cue, Z = f H / dy, takes the lower bottom edge for a nearer
    # car) and the range shrinks too slowly; with the ego's path the row stands where it is
    # and closes in at the ego's speed.
    path = straight_path(10.0)
    boxes, truth = _parked_row(path, -0.35)
    alone = range_tracks(boxes, CAM)
    moving = range_tracks(boxes, CAM, ego_path=path)

    def rel(result):
        return np.array([(b.range_m - truth[(b.frame, b.track_id)]) / truth[(b.frame,
                         b.track_id)] for b in result.boxes])

    assert np.median(rel(alone)) < -0.04
    assert abs(np.median(rel(moving))) < 0.015 and np.percentile(np.abs(rel(moving)), 90) < 0.04
    assert moving.standing_tracks == frozenset({1, 2, 3, 4})
    rates = np.array([b.range_rate_mps for b in moving.boxes])
    assert np.nanmedian(np.abs(rates + 10.0)) < 0.15
    for tid in range(1, 5):
        height, _, source = moving.ground_m_by_track[tid]
        assert source == "standing fit" and height == pytest.approx(-0.35, abs=0.06)


def test_a_lead_driving_ahead_is_not_taken_for_a_standing_car():
    path = straight_path(10.0)
    boxes, truth = standing_boxes(path, (20.0, 0.0), along_mps=7.0, t_span=(0.0, 4.0))
    result = range_tracks(boxes, CAM, ego_path=path)
    assert not result.standing_tracks
    rel = np.array([(b.range_m - x) / x for b, x in zip(result.boxes, truth, strict=True)])
    assert np.median(np.abs(rel)) < 0.04


def test_bottom_below_the_image_keeps_the_learnt_scale():
    # A lead straight ahead closing from 14 to 4 m: its bottom leaves a 300-row image at
    # about 6 m. The cut frames keep the range the visible frames measured.
    cam = Camera(image_width=1242, image_height=300, fx=721.5, fy=721.5, cx=609.6, cy=172.9,
                 height_m=1.65)
    path = straight_path(0.0, duration_s=6.0, noise_m=None)
    boxes, truth = standing_boxes(path, (14.0, 0.0), along_mps=-2.0, t_span=(0.0, 5.0),
                                  camera=cam)
    result = range_tracks(boxes, cam)
    cut = np.array([b.y2 >= cam.image_height - 2 for b in boxes])
    assert cut.sum() >= 10 and (~cut).sum() >= 10
    rel = np.array([(b.range_m - x) / x for b, x in zip(result.boxes, truth, strict=True)])
    assert np.median(np.abs(rel[cut])) < 0.05 and abs(np.median(rel[cut])) < 0.04
    assert any("learnt while its bottom was visible" in str(n) for n in result.warnings)


def test_a_car_parked_crosswise_beside_the_road_stands_at_its_nearest_face():
    # A car in a car park's bay 20 m to the left, its long axis across the road (KITTI raw
    # 0001's car park): its box is its flank and its nearest face, which no car parallel to
    # the road explains; fitted crosswise it stands, its range the near face's depth.
    path = straight_path(8.0)
    centre = (45.0, 20.0)
    shape = shape_matrix([CLASS_SHAPES["car"]])
    rng = np.random.default_rng(3)
    boxes, truth = [], []
    for k, t in enumerate(path.t_s):
        if t > 2.5 + 1e-9:
            break
        ex, eh = float(np.interp(t, path.t_s, path.x_m)), 0.0
        cx, cy = centre[0] - ex, centre[1]
        box = outline_boxes(CAM, np.array([cx - L / 2]), np.array([cy]), np.array([W]),
                            np.array([H]), np.array([L]), shape, math.pi / 2 - eh)[0]
        if box[0] < 10:
            break
        b = box + rng.normal(0, 0.5, 4)
        boxes.append(TrackedBox(k, round(float(t), 6), 1, "car", 0.9, *b))
        truth.append(cx - W / 2)
    result = range_tracks(boxes, CAM, ego_path=path)
    assert 1 in result.standing_tracks
    rel = np.array([b.range_m for b in result.boxes]) / np.array(truth) - 1
    assert np.median(np.abs(rel)) < 0.03
    rates = np.array([b.range_rate_mps for b in result.boxes])
    assert np.nanmedian(np.abs(rates + 8.0)) < 0.3


def _crosswise_boxes(path: EgoPath, centre: tuple[float, float], ground_m: float,
                     track_id: int, t_end: float = 2.5) -> list[TrackedBox]:
    """Boxes of a car standing across the road (long axis across the ego's travel)."""
    shape = shape_matrix([CLASS_SHAPES["car"]])
    rng = np.random.default_rng(track_id)
    boxes = []
    for k, t in enumerate(path.t_s):
        if t > t_end + 1e-9:
            break
        cx = centre[0] - float(np.interp(t, path.t_s, path.x_m))
        box = outline_boxes(CAM, np.array([cx - L / 2]), np.array([centre[1]]), np.array([W]),
                            np.array([H]), np.array([L]), shape, math.pi / 2, z_m=ground_m)[0]
        if box[0] < 10:
            break
        boxes.append(TrackedBox(k, round(float(t), 6), track_id, "car", 0.9,
                                *(box + rng.normal(0, 0.5, 4))))
    return boxes


def test_a_car_park_on_a_road_that_falls_across_stands_on_that_fall():
    # The road falls 4.75 % to the left: a parked row 8 m to the left stands 0.38 m below
    # the ego's plane, a car park 20 m to the left 0.95 m below, beyond the 0.8 m that a
    # kerb or a strip puts a car off the road under it. Alone the car-park car is no
    # plausible standing car; with the row measuring the fall it stands on it.
    path = straight_path(8.0)
    car_park = _crosswise_boxes(path, (45.0, 20.0), -0.95, 9)
    alone = range_tracks(car_park, CAM, ego_path=path)
    assert 9 not in alone.standing_tracks
    row = [b for i, x in enumerate((30.0, 36.0, 42.0))
           for b in standing_boxes(path, (x, 8.0), track_id=i + 1, ground_m=-0.38,
                                   t_span=(0.0, 2.5), seed=i)[0]]
    result = range_tracks(row + car_park, CAM, ego_path=path)
    assert {1, 2, 3, 9} <= result.standing_tracks
    assert result.ground_m_by_track[9][0] == pytest.approx(-0.95, abs=0.1)
    assert result.ground_m_by_track[9][2] == "standing fit"
