"""Pinhole camera: projection known answers, ground back-projection round trips, horizon,
boxes, defaults, YAML and KITTI calibration readers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.base.errors import (
    FormatError,
    ImpossibleValueError,
    InconsistentInputError,
    MissingInputError,
)
from vid2sim.core.camera import (
    DEFAULT_HFOV_DEG,
    KITTI_CAMERA_HEIGHT_M,
    Camera,
    load_camera,
)

CONTRACT_YAML = """\
image_width: 1242
image_height: 375
fx: 721.5377
fy: 721.5377
cx: 609.5593
cy: 172.854
dist: [0.0, 0.0, 0.0, 0.0, 0.0]   # k1 k2 p1 p2 k3, OpenCV order
height_m: 1.65                    # camera above the road
pitch_deg: 0.0                    # positive looks down
yaw_deg: 0.0                      # positive looks left
roll_deg: 0.0
"""


@pytest.fixture
def kitti_cam(tmp_path) -> Camera:
    f = tmp_path / "camera.yaml"
    f.write_text(CONTRACT_YAML)
    return load_camera(f)


def test_yaml_contract_fields(kitti_cam):
    c = kitti_cam
    assert (c.image_width, c.image_height) == (1242, 375)
    assert (c.fx, c.fy, c.cx, c.cy) == (721.5377, 721.5377, 609.5593, 172.854)
    assert c.dist == (0.0,) * 5 and c.height_m == 1.65 and c.pitch_deg == 0.0
    assert Camera.from_dict(c.to_dict()) == c


def test_projection_known_answers(kitti_cam):
    c = kitti_cam
    pts = np.array([
        [10.0, 0.0, 1.65],   # on the optical axis -> principal point
        [10.0, 0.0, 0.0],    # on the road 10 m ahead -> fy * h / x below cy
        [20.0, 2.0, 1.65],   # 2 m to the LEFT -> left of cx (u smaller)
        [-5.0, 0.0, 0.0],    # behind the camera
    ])
    uv, ok = c.project(pts)
    assert ok.tolist() == [True, True, True, False]
    assert uv[0] == pytest.approx((c.cx, c.cy))
    assert uv[1] == pytest.approx((c.cx, c.cy + c.fy * 1.65 / 10.0))
    assert uv[2] == pytest.approx((c.cx - c.fx * 2.0 / 20.0, c.cy))
    assert np.all(np.isnan(uv[3]))


def test_pitch_and_yaw_signs(kitti_cam):
    ahead = np.array([[30.0, 0.0, 1.65]])
    down = kitti_cam.with_pitch(5.0)  # looks down: things ahead at eye level move UP the image
    assert down.project(ahead)[0][0, 1] < kitti_cam.cy
    assert down.project(ahead)[0][0, 1] == pytest.approx(
        kitti_cam.cy - kitti_cam.fy * math.tan(math.radians(5.0)))
    left = Camera.from_dict({**kitti_cam.to_dict(), "yaw_deg": 10.0})  # looks left
    assert left.project(ahead)[0][0, 0] > kitti_cam.cx  # straight ahead is now right of centre


@pytest.mark.parametrize("pitch", [-3.0, 0.0, 2.0, 8.0])
def test_horizon_row(kitti_cam, pitch):
    cam = kitti_cam.with_pitch(pitch)
    assert cam.horizon_y_px() == pytest.approx(cam.cy - cam.fy * math.tan(math.radians(pitch)))
    # A far point on the road projects just below the horizon.
    far = cam.project(np.array([[5000.0, 0.0, 0.0]]))[0][0, 1]
    assert far == pytest.approx(cam.horizon_y_px(), abs=0.5)
    assert far > cam.horizon_y_px()


def test_pixel_to_ground_known_answer_and_above_horizon(kitti_cam):
    pts, ok = kitti_cam.pixel_to_ground(np.array([
        [kitti_cam.cx, kitti_cam.cy + kitti_cam.fy * 1.65 / 10.0],
        [kitti_cam.cx, kitti_cam.cy - 10.0],  # above the horizon: the ray never meets the road
    ]))
    assert ok.tolist() == [True, False]
    assert pts[0] == pytest.approx((10.0, 0.0, 0.0), abs=1e-9)
    assert np.all(np.isnan(pts[1]))


@settings(max_examples=60, deadline=None)
@given(x=st.floats(3.0, 80.0), y=st.floats(-10.0, 10.0), pitch=st.floats(-3.0, 8.0),
       yaw=st.floats(-5.0, 5.0), roll=st.floats(-3.0, 3.0), k1=st.floats(-0.3, 0.1))
def test_ground_round_trip_property(x, y, pitch, yaw, roll, k1):
    cam = Camera(image_width=1242, image_height=375, fx=721.5, fy=721.5, cx=609.6, cy=172.9,
                 dist=(k1, 0.0, 0.0, 0.0, 0.0), height_m=1.5, pitch_deg=pitch, yaw_deg=yaw,
                 roll_deg=roll)
    uv, ok = cam.project(np.array([[x, y, 0.0]]))
    assert ok[0]
    ideal = Camera(**{**cam.to_dict(), "dist": (0.0,) * 5}).project(np.array([[x, y, 0.0]]))[0]
    inside = [(0 <= q[0, 0] < 1242 and 0 <= q[0, 1] < 375) for q in (uv, ideal)]
    if not all(inside):
        # Only points the lens images inside the frame; far outside it the radial polynomial
        # folds back (k1 < 0) and has no unique inverse.
        return
    back, below = cam.pixel_to_ground(uv)
    assert below[0]
    assert back[0] == pytest.approx((x, y, 0.0), abs=1e-3 * max(1.0, x))


def test_distorted_projection_matches_rays():
    cam = Camera(image_width=1392, image_height=512, fx=984.2, fy=980.8, cx=690.0, cy=233.2,
                 dist=(-0.3729, 0.2037, 0.0022, 0.0014, -0.0723), height_m=1.65)
    pts = np.array([[12.0, 3.0, 0.5], [25.0, -4.0, 2.0], [8.0, 1.0, 1.0]])
    uv, ok = cam.project(pts)
    assert ok.all()
    rays = cam.pixel_rays_veh(uv)
    want = pts - cam.position_veh_m
    want /= np.linalg.norm(want, axis=1, keepdims=True)
    assert rays == pytest.approx(want, abs=1e-6)
    # Barrel distortion (k1 < 0) pulls off-centre points towards the centre.
    plain = Camera(**{**cam.to_dict(), "dist": (0.0,) * 5})
    r_d = np.hypot(*(uv - (cam.cx, cam.cy)).T)
    r_p = np.hypot(*(plain.project(pts)[0] - (cam.cx, cam.cy)).T)
    assert np.all(r_d < r_p)


def test_project_box(kitti_cam):
    box = kitti_cam.project_box(np.array([15.0, 0.0]), 4.5, 1.8, 1.5)
    assert box is not None
    x1, _, x2, y2 = box
    centre_bottom = kitti_cam.project(np.array([[15.0 - 2.25, 0.0, 0.0]]))[0][0]
    assert x1 < kitti_cam.cx < x2
    assert y2 == pytest.approx(centre_bottom[1], abs=1e-6)  # rear bottom edge is lowest
    assert (x2 - x1) == pytest.approx(kitti_cam.fx * 1.8 / 12.75, rel=1e-6)
    assert kitti_cam.project_box(np.array([-10.0, 0.0]), 4.5, 1.8, 1.5) is None  # behind
    assert kitti_cam.project_box(np.array([15.0, 80.0]), 4.5, 1.8, 1.5) is None  # off image
    yawed = kitti_cam.project_box(np.array([15.0, 0.0]), 4.5, 1.8, 1.5, yaw_rad=math.pi / 2)
    assert (yawed[2] - yawed[0]) > (x2 - x1)  # sideways the car shows its length


def test_default_camera_field_of_view_and_assumption():
    cam = Camera.default_for(1920, 1080)
    ray = cam.pixel_rays_veh(np.array([[-0.5, cam.cy]]))[0]  # the left image edge
    assert math.degrees(math.atan2(ray[1], ray[0])) == pytest.approx(DEFAULT_HFOV_DEG / 2, abs=0.01)
    assert cam.assumptions and "field of view" in cam.assumptions[0]


def test_scaled_camera_keeps_rays(kitti_cam):
    half = kitti_cam.scaled_to(621, 187)
    pt = np.array([[20.0, 3.0, 0.0]])
    uv_full = kitti_cam.project(pt)[0][0]
    uv_half = half.project(pt)[0][0]
    assert uv_half == pytest.approx(uv_full * (621 / 1242, 187 / 375), rel=1e-9)


def test_kitti_calibration_real(kitti_raw_dir):
    cam = load_camera(kitti_raw_dir / "calib_cam_to_cam.txt")
    assert (cam.image_width, cam.image_height) == (1242, 375)
    assert cam.fx == pytest.approx(721.5377) and cam.cx == pytest.approx(609.5593)
    assert cam.height_m == KITTI_CAMERA_HEIGHT_M and cam.dist == (0.0,) * 5
    yaml_cam = load_camera(kitti_raw_dir / "camera.yaml")
    assert yaml_cam.fx == pytest.approx(cam.fx) and yaml_cam.cy == pytest.approx(cam.cy)


def test_kitti_tracking_calibration_text(tmp_path):
    p2 = "7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 7.215377e+02 " \
         "1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 2.745884e-03"
    f = tmp_path / "0001.txt"
    f.write_text(f"P0: {p2}\nP1: {p2}\nP2: {p2}\nP3: {p2}\nR_rect 1 0 0 0 1 0 0 0 1\n")
    cam = load_camera(f)
    assert cam.fy == pytest.approx(721.5377) and cam.cy == pytest.approx(172.854)
    assert any("1242x375" in a for a in cam.assumptions)


@pytest.mark.parametrize("text,error,datum", [
    ("image_width: 100\nimage_height: 50\nfx: 10\n", FormatError, "fy"),  # the keys missing
    (CONTRACT_YAML.replace("dist: [0.0, 0.0, 0.0, 0.0, 0.0]", "dist: [0.1, 0.2, 0.3]"),
     FormatError, "dist"),
    (CONTRACT_YAML.replace("fx: 721.5377", "fx: -1"), ImpossibleValueError, ""),
    (CONTRACT_YAML.replace("fx: 721.5377", "fx: wide"), FormatError, "wide"),
    (CONTRACT_YAML.replace("height_m: 1.65", "height_m: 40"), ImpossibleValueError, "height_m"),
    ("image_width: [1, 2\n", FormatError, ""),  # not YAML
    ("- just\n- a list\n", FormatError, ""),  # not a mapping
    ("P2: 1 2 3\n", FormatError, "camera 2"),  # no 3x4 projection
])
def test_camera_file_errors(tmp_path, text, error, datum):
    f = tmp_path / "cam.yaml"
    f.write_text(text)
    with pytest.raises(error, match=datum) as e:
        load_camera(f)
    assert "cam.yaml" in str(e.value)


def test_missing_camera_file(tmp_path):
    with pytest.raises(MissingInputError):
        load_camera(tmp_path / "nope.yaml")


def test_camera_for_cropped_resized_and_foreign_frames():
    from vid2sim.core.camera import fit_camera_to_frames

    cam = Camera(image_width=1242, image_height=375, fx=721.5, fy=721.5, cx=609.6, cy=172.9)
    cropped, note = fit_camera_to_frames(cam, 1224, 370)  # KITTI 0016: a crop, not a resize
    assert "crop" in note
    assert (cropped.fx, cropped.cx, cropped.image_width, cropped.image_height) == (
        721.5, 609.6, 1224, 370)
    halved, note = fit_camera_to_frames(cam, 621, 187)
    assert "resize" in note
    assert halved.fx == pytest.approx(360.75) and halved.cx == pytest.approx(304.8)
    same, note = fit_camera_to_frames(cam, 1242, 375)
    assert same is cam and note is None
    with pytest.raises(InconsistentInputError, match=r"cam.yaml: .*1242x375.*1280x720"):
        fit_camera_to_frames(cam, 1280, 720, "cam.yaml")


# --------------------------------------------------------------------------- damaged files


def _damage_strategies():
    from tests.damage import damaged

    yaml_text = CONTRACT_YAML.encode()
    kitti = (b"P_rect_02: 7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 "
             b"7.215377e+02 1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 "
             b"2.745884e-03\nS_rect_02: 1.242000e+03 3.750000e+02\n")
    return st.one_of(damaged(yaml_text), damaged(kitti))


def test_camera_file_damage_gives_input_error_only(tmp_path):
    from tests.damage import FUZZ, input_error_or_result

    @FUZZ
    @given(data=_damage_strategies())
    def check(data):
        f = tmp_path / "cam.yaml"
        f.write_bytes(data)
        cam = input_error_or_result(load_camera, f)
        if isinstance(cam, Camera):  # a camera that loads is a usable one
            assert np.isfinite(cam.horizon_y_px())

    check()


_V = ImpossibleValueError


@pytest.mark.parametrize("line,error,datum", [
    ("fx: .nan", _V, "fx"), ("cx: .inf", _V, "cx"), ("pitch_deg: 1e6", _V, "pitch_deg"),
    ("fx: 0.5", _V, "fx 0.5"), ("fy: 100000", _V, "fy 100000"), ("cx: 5000", _V, "5000"),
    ("image_width: 1242.5", FormatError, "image_width"),  # not a whole number of pixels
    ("dist: [1e9, 0, 0, 0, 0]", _V, r"1000000000\.0"),
    ("roll_deg: 90", _V, "roll_deg"), ("height_m: .nan", _V, "height_m"),
])
def test_every_camera_number_is_checked_finite_and_physical(tmp_path, line, error, datum):
    key = line.split(":")[0]
    text = "\n".join(line if row.startswith(key + ":") else row
                     for row in CONTRACT_YAML.splitlines())
    f = tmp_path / "cam.yaml"
    f.write_text(text)
    with pytest.raises(error, match=datum):
        load_camera(f)


def test_kitti_calibration_with_nan_is_an_input_error(tmp_path):
    f = tmp_path / "calib.txt"
    f.write_text("P2: nan 0 609.5 0 0 721.5 172.8 0 0 0 1 0\n")
    with pytest.raises(ImpossibleValueError, match="fx"):
        load_camera(f)
