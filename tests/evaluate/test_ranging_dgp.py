"""The DGP reader and the ranging truth it gives: property tests on generated scenes, then the
real TRI scenes (skipped when ../shared is absent)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import DATA
from vid2sim.base.errors import (
    FormatError,
    ImpossibleValueError,
    InconsistentInputError,
    MissingInputError,
)
from vid2sim.core.camera import Camera
from vid2sim.evaluate.ranging.dgp import (
    DgpCuboid,
    DgpFrame,
    calibration_camera,
    camera_on_plane,
    cuboid_range_m,
    fit_ground_plane,
    ground_camera,
    quaternion_to_matrix,
    read_dgp_scene,
)

ONTOLOGY = {"items": [{"id": 2, "name": "Car"}, {"id": 1, "name": "Truck"},
                      {"id": 0, "name": "Person"}]}

finite = st.floats(-50, 50, allow_nan=False)
quats = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 4).filter(
    lambda q: np.linalg.norm(q) > 0.1)
sizes = st.floats(0.3, 20.0, allow_nan=False)
cuboid_st = st.fixed_dictionaries({
    "center": st.tuples(finite, finite, st.floats(1, 120, allow_nan=False)),
    "q": quats, "length": sizes, "width": sizes, "height": sizes,
    "class_id": st.sampled_from([0, 1, 2]), "instance_id": st.integers(0, 2 ** 32 - 1),
    "num_points": st.integers(0, 10000)})


def _write_scene(root: Path, frames: list[list[dict]], intr=(2000.0, 2000.0, 960.0, 600.0),
                 ext_z: float = 1.5) -> Path:
    """A minimal DGP scene folder with one CAMERA_01 datum per frame (and a LIDAR datum whose
    files are absent, which the reader must skip)."""
    scene = root / "scene_x"
    for sub in ("calibration", "ontology", "rgb/CAMERA_01", "bounding_box_3d/CAMERA_01",
                "bounding_box_2d/CAMERA_01"):
        (scene / sub).mkdir(parents=True, exist_ok=True)
    (scene / "ontology" / "ont.json").write_text(json.dumps(ONTOLOGY))
    fx, fy, cx, cy = intr
    calib = {"names": ["LIDAR", "CAMERA_01"],
             "intrinsics": [{"fx": 0, "fy": 0, "cx": 0, "cy": 0, "skew": 0},
                            {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "skew": 0}],
             "extrinsics": [{"rotation": {"qw": 1, "qx": 0, "qy": 0, "qz": 0},
                             "translation": {"x": 0, "y": 0, "z": 0}},
                            {"rotation": {"qw": 0.5, "qx": -0.5, "qy": 0.5, "qz": -0.5},
                             "translation": {"x": 1.6, "y": 0.0, "z": ext_z}}]}
    (scene / "calibration" / "cal.json").write_text(json.dumps(calib))
    samples, data = [], []
    for k, cuboids in enumerate(frames):
        stamp = f"2019-05-03T21:39:{k:02d}.415230Z"
        anns3 = [{"box": {"height": c["height"], "length": c["length"], "width": c["width"],
                          "occlusion": 0, "truncation": 0.0,
                          "pose": {"rotation": dict(zip(("qw", "qx", "qy", "qz"), c["q"],
                                                        strict=True)),
                                   "translation": dict(zip("xyz", c["center"], strict=True))}},
                  "class_id": c["class_id"], "instance_id": c["instance_id"],
                  "num_points": c["num_points"], "attributes": {}} for c in cuboids]
        anns2 = [{"box": {"x": 10 + i, "y": 20, "w": 30, "h": 40}, "class_id": c["class_id"],
                  "instance_id": c["instance_id"], "area": 1200, "iscrowd": False}
                 for i, c in enumerate(cuboids)]
        (scene / "bounding_box_3d/CAMERA_01" / f"{k}.json").write_text(
            json.dumps({"annotations": anns3}))
        (scene / "bounding_box_2d/CAMERA_01" / f"{k}.json").write_text(
            json.dumps({"annotations": anns2}))
        (scene / "rgb/CAMERA_01" / f"{k}.jpg").write_bytes(b"\xff\xd8\xff")
        data.append({"key": f"cam{k}", "id": {"name": "CAMERA_01", "timestamp": stamp},
                     "datum": {"image": {"filename": f"rgb/CAMERA_01/{k}.jpg", "width": 1936,
                                         "height": 1216,
                                         "annotations": {"0": f"bounding_box_2d/CAMERA_01/{k}.json",
                                                         "1": f"bounding_box_3d/CAMERA_01/{k}.json"}}}})
        data.append({"key": f"lidar{k}", "id": {"name": "LIDAR", "timestamp": stamp},
                     "datum": {"point_cloud": {"filename": f"point_cloud/LIDAR/{k}.npz"}}})
        samples.append({"calibration_key": "cal", "datum_keys": [f"lidar{k}", f"cam{k}"]})
    doc = {"data": data, "samples": samples, "ontologies": {"0": "ont", "1": "ont"}}
    (scene / "scene_abc.json").write_text(json.dumps(doc))
    return scene


@settings(max_examples=60)
@given(q=quats)
def test_quaternion_gives_a_rotation(q):
    r = quaternion_to_matrix(*q)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(quaternion_to_matrix(*(-np.asarray(q))), r, atol=1e-12)


def test_quaternion_known_answer_and_bad_input():
    # 90 deg about z: x -> y.
    r = quaternion_to_matrix(math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4))
    np.testing.assert_allclose(r @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    with pytest.raises(ValueError):
        quaternion_to_matrix(0, 0, 0, 0)
    with pytest.raises(ValueError):
        quaternion_to_matrix(float("nan"), 0, 0, 1)


@settings(max_examples=25, deadline=None)
@given(frames=st.lists(st.lists(cuboid_st, max_size=5), min_size=1, max_size=3))
def test_scene_round_trip(tmp_path_factory, frames):
    scene = _write_scene(tmp_path_factory.mktemp("dgp"), frames)
    got = read_dgp_scene(scene)
    assert len(got) == len(frames)
    assert [f.t_s for f in got] == sorted(f.t_s for f in got)
    names = {0: "Person", 1: "Truck", 2: "Car"}
    for frame, cuboids in zip(got, frames, strict=True):
        assert (frame.fx, frame.cy, frame.width_px) == (2000.0, 600.0, 1936)
        assert len(frame.cuboids) == len(cuboids) == len(frame.boxes_2d)
        for c, want in zip(frame.cuboids, cuboids, strict=True):
            assert c.class_name == names[want["class_id"]]
            assert c.instance_id == want["instance_id"]
            np.testing.assert_allclose(c.center_m, want["center"])
            assert (c.length_m, c.width_m, c.height_m) == (want["length"], want["width"],
                                                           want["height"])
            np.testing.assert_allclose(np.asarray(c.rotation), quaternion_to_matrix(*want["q"]))
        for b, want in zip(frame.boxes_2d, cuboids, strict=True):
            assert b.instance_id == want["instance_id"] and b.box_px[2] - b.box_px[0] == 30


@settings(max_examples=50)
@given(c=cuboid_st)
def test_cuboid_corners_span_its_size(c):
    cub = DgpCuboid(1, "Car", c["center"], tuple(map(tuple, quaternion_to_matrix(*c["q"]))),
                    c["length"], c["width"], c["height"], 0, 0, 0.0)
    local = (cub.corners_m() - np.asarray(c["center"])) @ np.asarray(cub.rotation)
    np.testing.assert_allclose(local.max(0) - local.min(0),
                               [c["length"], c["width"], c["height"]], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(cub.bottom_center_m(), cub.corners_m()[:4].mean(0), atol=1e-9)


@settings(max_examples=50)
@given(height=st.floats(0.8, 3.0), pitch=st.floats(-4, 4), roll=st.floats(-3, 3),
       seed=st.integers(0, 1000))
def test_ground_plane_and_camera_recover_a_known_mounting(height, pitch, roll, seed):
    # Points on the road of a camera mounted at a known height, pitch and roll, expressed in
    # its camera frame: the plane fit and the camera built on it must give the mounting back.
    frame = DgpFrame("s", 0.0, Path("x.jpg"), 1936, 1216, 2000.0, 2000.0, 968.0, 608.0, (), ())
    true = Camera(1936, 1216, 2000.0, 2000.0, 968.0, 608.0, height_m=height, pitch_deg=pitch,
                  roll_deg=roll)
    rng = np.random.default_rng(seed)
    road = np.column_stack((rng.uniform(5, 60, 12), rng.uniform(-10, 10, 12), np.zeros(12)))
    normal, h, rms = fit_ground_plane(true.vehicle_to_camera(road))
    assert h == pytest.approx(height, abs=1e-9) and rms < 1e-9
    cam = camera_on_plane(frame, normal, h)
    assert cam.pitch_deg == pytest.approx(pitch, abs=1e-7)
    assert cam.roll_deg == pytest.approx(roll, abs=1e-7)


@settings(max_examples=40)
@given(rng_m=st.floats(2, 90), lat=st.floats(-12, 12), length=st.floats(3, 12),
       pitch=st.floats(-3, 3), height=st.floats(1.0, 2.5))
def test_cuboid_range_is_its_rear_face(rng_m, lat, length, pitch, height):
    # A box driving ahead along the road: rear face at rng_m, centre lateral lat.
    cam = Camera(1936, 1216, 2000.0, 2000.0, 968.0, 608.0, height_m=height, pitch_deg=pitch)
    centre_veh = np.array([[rng_m + length / 2, lat, 0.8]])
    centre_cam = cam.vehicle_to_camera(centre_veh)[0]
    # Box axes (length along vehicle x, width along y, height along z) in camera coordinates.
    rot = cam.R_veh_from_cam.T
    cub = DgpCuboid(1, "Car", tuple(centre_cam), tuple(map(tuple, rot)), length, 1.8, 1.6, 0, 0,
                    0.0)
    r, y = cuboid_range_m(cub, cam)
    assert r == pytest.approx(rng_m, abs=1e-9) and y == pytest.approx(lat, abs=1e-9)


def test_malformed_scenes_are_input_errors(tmp_path):
    with pytest.raises(MissingInputError):  # no scene_*.json
        read_dgp_scene(tmp_path)
    good = [{"center": (1.0, 0.5, 10.0), "q": (1.0, 0, 0, 0), "length": 4.0, "width": 1.8,
             "height": 1.5, "class_id": 2, "instance_id": 7, "num_points": 5}]
    scene = _write_scene(tmp_path / "a", [good])
    box = scene / "bounding_box_3d/CAMERA_01/0.json"
    doc = json.loads(box.read_text())
    doc["annotations"][0]["box"]["width"] = -1.0
    box.write_text(json.dumps(doc))
    with pytest.raises(ImpossibleValueError, match="width"):
        read_dgp_scene(scene)
    doc["annotations"][0]["box"]["width"] = 1.8
    del doc["annotations"][0]["box"]["pose"]
    box.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="pose"):
        read_dgp_scene(scene)
    box.write_text("{not json")
    with pytest.raises(FormatError, match="line 1"):
        read_dgp_scene(scene)
    other = _write_scene(tmp_path / "b", [good])
    cal = other / "calibration" / "cal.json"
    cal.write_text(json.dumps({**json.loads(cal.read_text()), "names": ["LIDAR", "CAMERA_09"]}))
    with pytest.raises(FormatError, match="CAMERA_01"):
        read_dgp_scene(other)
    with pytest.raises(InconsistentInputError):  # one car cannot give the ground
        ground_camera(read_dgp_scene(_write_scene(tmp_path / "c", [good]))[0])


# --------------------------------------------------------------------------- real scenes


@pytest.fixture(scope="module")
def tri_dir() -> Path:
    path = DATA / "tri_dgp_front"
    if not path.exists():
        pytest.skip(f"TRI DGP scenes not found at {path} (set VID2SIM_SHARED)")
    return path


def test_tri_scene_01_reads_and_has_a_ground(tri_dir):
    frames = read_dgp_scene(tri_dir / "scene_01")
    assert len(frames) == 3
    assert len(frames[0].cuboids) == 24 and all(len(f.cuboids) >= 20 for f in frames)
    assert all(f.image.exists() and (f.width_px, f.height_px) == (1936, 1216) for f in frames)
    cam, rms, n = ground_camera(frames[0])
    # The README: the car ahead has its cuboid centre 8.75 m ahead and its rear ~6.3 m away;
    # the cuboids' ground puts the camera 1.40 m above the road (the extrinsics: 1.36 m).
    assert n >= 8 and rms < 0.2
    assert cam.height_m == pytest.approx(1.40, abs=0.05)
    assert calibration_camera(frames[0]).height_m == pytest.approx(1.355, abs=0.01)
    lead = min((c for c in frames[0].cuboids if c.class_name == "Car"),
               key=lambda c: abs(c.center_m[0]) + c.center_m[2])
    r, lat = cuboid_range_m(lead, cam)
    assert r == pytest.approx(6.3, abs=0.1) and abs(lat) < 1.0
    # Its 2D box is linked by instance id.
    assert any(b.instance_id == lead.instance_id for b in frames[0].boxes_2d)


def test_tri_scene_02_far_cars_only(tri_dir):
    frames = read_dgp_scene(tri_dir / "scene_02")
    assert len(frames) == 3
    with pytest.raises(InconsistentInputError):  # no car within 50 m to fit the ground on
        ground_camera(frames[0])
    cam = calibration_camera(frames[0])
    ranges = sorted(cuboid_range_m(c, cam)[0] for c in frames[0].cuboids)
    assert 60 < ranges[0] < 70  # "a car 67-69 m ahead, nearly in line"
