"""KITTI raw tracklets: the XML parser, the velodyne -> camera geometry, the truth table, the
keyframes made of them; known answers, property tests and the real drive 0001."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vid2sim.base.errors import FormatError, ImpossibleValueError, MissingInputError
from vid2sim.evaluate.annotations import read_keyframes
from vid2sim.evaluate.ranging.static import ego_motion
from vid2sim.evaluate.ranging.tracklets import (
    RawCalibration,
    Tracklet,
    box_corners_velo,
    calibration_beside,
    central_difference,
    hull_box_px,
    parse_tracklets,
    read_tracklets,
    tracklet_truth,
)
from vid2sim.evaluate.tracklet_keyframes import TrackletKeyframeConfig, keyframe_stride

F, CX, CY = 700.0, 600.0, 180.0
# Velodyne (x forward, y left, z up) -> camera (x right, y down, z forward), no offset.
AXES = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
CALIB = RawCalibration(AXES, np.zeros(3), np.eye(3),
                       np.array([[F, 0, CX, 0], [0, F, CY, 0], [0, 0, 1, 0]], dtype=float))


def _pose_xml(pose, flags) -> str:
    body = "".join(f"<{k}>{v!r}</{k}>" for k, v in zip(("tx", "ty", "tz", "rx", "ry", "rz"),
                                                         map(float, pose), strict=True))
    body += "".join(f"<{k}>{int(v)}</{k}>" for k, v in zip(("state", "occlusion", "truncation"),
                                                          flags, strict=True))
    return f"<item>{body}<amt_occlusion>0</amt_occlusion></item>"


def tracklet_xml(objects: list[dict]) -> str:
    """A boost-serialization tracklet file as KITTI writes it (the fields the reader uses and
    a few it skips)."""
    items = []
    for o in objects:
        poses = "".join(_pose_xml(p, f) for p, f in zip(o["pose"], o["flags"], strict=True))
        items.append(f"<item class_id='1' tracking_level='0' version='1'>"
                     f"<objectType>{o['type']}</objectType><h>{o['h']!r}</h><w>{o['w']!r}</w>"
                     f"<l>{o['l']!r}</l><first_frame>{o['first']}</first_frame>"
                     f"<poses class_id='2'><count>{len(o['pose'])}</count>"
                     f"<item_version>2</item_version>{poses}</poses><finished>1</finished>"
                     f"</item>")
    return ("<?xml version='1.0' encoding='UTF-8' standalone='yes' ?>\n"
            "<!DOCTYPE boost_serialization>\n<boost_serialization signature='serialization::"
            f"archive' version='9'><tracklets class_id='0'><count>{len(objects)}</count>"
            f"<item_version>1</item_version>{''.join(items)}</tracklets></boost_serialization>")


def _write_calib(folder: Path) -> None:
    folder.joinpath("calib_velo_to_cam.txt").write_text(
        "calib_time: x\nR: " + " ".join(map(str, AXES.ravel())) + "\nT: 0 0 0\n")
    folder.joinpath("calib_cam_to_cam.txt").write_text(
        "R_rect_00: 1 0 0 0 1 0 0 0 1\n"
        f"P_rect_00: {F} 0 {CX} 0 0 {F} {CY} 0 0 0 1 0\n")


# --------------------------------------------------------------------------- geometry


def test_box_corners_known_answer():
    c = box_corners_velo((1.5, 2.0, 4.0), np.array([10.0, 1.0, -1.7, 0, 0, 0]))
    assert sorted(set(np.round(c[:, 0], 9))) == [8.0, 12.0]
    assert sorted(set(np.round(c[:, 1], 9))) == [0.0, 2.0]
    assert sorted(set(np.round(c[:, 2], 9))) == [-1.7, -0.2]
    turned = box_corners_velo((1.5, 2.0, 4.0), np.array([10.0, 0.0, 0.0, 0, 0, math.pi / 2]))
    assert np.ptp(turned[:, 0]) == pytest.approx(2.0) and np.ptp(turned[:, 1]) == pytest.approx(4.0)


@given(st.floats(-math.pi, math.pi), st.floats(0.5, 5), st.floats(0.5, 3), st.floats(1, 20))
def test_box_corners_rigid(yaw, h, w, length):
    # Whatever the yaw: the footprint is a w x l rectangle about (tx, ty), the top h above.
    c = box_corners_velo((h, w, length), np.array([3.0, -2.0, 0.5, 0, 0, yaw]))
    assert np.allclose(c[:4].mean(axis=0), [3.0, -2.0, 0.5])
    assert np.allclose(c[4:, 2] - c[:4, 2], h)
    assert np.linalg.norm(c[0] - c[1]) == pytest.approx(w)
    assert np.linalg.norm(c[1] - c[2]) == pytest.approx(length)


def test_velo_to_cam_and_projection_known_answer():
    p = CALIB.velo_to_cam(np.array([[10.0, 0.0, 0.0], [10.0, 1.0, -1.0]]))
    assert np.allclose(p, [[0, 0, 10], [-1, 1, 10]])
    uv = CALIB.project(p)
    assert np.allclose(uv, [[CX, CY], [CX - F / 10, CY + F / 10]])


def test_hull_box_in_view_cut_and_behind():
    corners = CALIB.velo_to_cam(box_corners_velo((1.5, 2.0, 4.0), np.array([10, 0, -1.65, 0, 0, 0])))
    box, frac, cut, margin = hull_box_px(corners, CALIB, 1242, 375)
    # nearest face 8 m: its bottom 1.65 m below the camera at 8 m is F * 1.65 / 8 under cy
    assert box[3] == pytest.approx(CY + F * 1.65 / 8)
    assert box[0] == pytest.approx(CX - F * 1.0 / 8) and frac == 1.0 and not cut
    assert margin == pytest.approx(CX - F * 1.0 / 8)
    near = CALIB.velo_to_cam(box_corners_velo((1.5, 2.0, 4.0), np.array([4, 0, -1.65, 0, 0, 0])))
    box, frac, cut, _ = hull_box_px(near, CALIB, 1242, 375)
    assert cut and box[3] == 374 and frac < 1.0
    behind = CALIB.velo_to_cam(box_corners_velo((1.5, 2.0, 4.0), np.array([-10, 0, 0, 0, 0, 0])))
    assert hull_box_px(behind, CALIB, 1242, 375)[0] is None


def test_central_difference_exact_on_lines_and_nan_at_gaps():
    frames = np.array([0, 1, 2, 3, 4, 5, 7, 8, 9])
    v = 30.0 - 1.2 * frames
    d = central_difference(frames, v, 2, 0.1)
    # both neighbours two frames away are needed (frame 6 is missing, what lies between is
    # not): frames 2, 3, 5 and 7 have them
    assert np.allclose(d[[2, 3, 5, 6]], -12.0)
    assert np.isnan(d[[0, 1, 4, 7, 8]]).all()


def test_truth_of_a_car_closing_at_known_speed():
    # A car 20 m ahead, 3 m left, driving towards the camera at 5 m/s (no ego motion known):
    # range = its rear corners' depth, rate -5 m/s, lateral its centre's.
    pose = np.array([[20.0 + 2.0 - 0.5 * k, 3.0, -1.65, 0, 0, 0] for k in range(10)])
    t = Tracklet(0, "Car", (1.5, 1.8, 4.0), 5, pose, np.zeros((10, 3), dtype=int))
    truth = tracklet_truth([t], CALIB, (1242, 375), camera_height_m=1.65, fps=10.0)
    assert list(truth.frame) == list(range(5, 15))
    assert truth.range_m[0] == pytest.approx(20.0)
    assert np.allclose(truth.range_rate_mps[2:-2], -5.0) and np.isnan(truth.range_rate_mps[:2]).all()
    assert np.allclose(truth.lateral_m, 3.0) and np.allclose(truth.ground_z_m, 0.0)
    assert np.isnan(truth.speed_mps).all() and not truth.parked.any()


# --------------------------------------------------------------------------- the parser


def _tracklets():
    pose = st.lists(st.floats(-80, 80, allow_nan=False), min_size=6, max_size=6)
    flags = st.tuples(st.integers(0, 2), st.integers(-1, 2), st.sampled_from([0, 1, 2, 99]))
    obj = st.integers(1, 6).flatmap(lambda n: st.fixed_dictionaries({
        "type": st.sampled_from(["Car", "Van", "Cyclist", "Tram", "Pedestrian"]),
        "h": st.floats(0.5, 4), "w": st.floats(0.4, 3), "l": st.floats(0.5, 40),
        "first": st.integers(0, 500), "pose": st.lists(pose, min_size=n, max_size=n),
        "flags": st.lists(flags, min_size=n, max_size=n)}))
    return st.lists(obj, max_size=4)


@given(_tracklets())
def test_parser_round_trip(objects):
    got = parse_tracklets(tracklet_xml(objects), Path("t.xml"))
    assert len(got) == len(objects)
    for o, t in zip(objects, got, strict=True):
        assert (t.object_type, t.size_hwl_m, t.first_frame) == (o["type"], (o["h"], o["w"], o["l"]),
                                                               o["first"])
        assert np.array_equal(t.pose, np.array(o["pose"]).reshape(-1, 6))
        assert np.array_equal(t.flags, np.array(o["flags"]).reshape(-1, 3))
        assert list(t.frames) == list(range(o["first"], o["first"] + len(o["pose"])))


@given(st.text(max_size=200))
def test_parser_rejects_anything_else_as_format_error(text):
    with pytest.raises(FormatError):
        parse_tracklets(text, Path("t.xml"))


GOOD = {"type": "Car", "h": 1.5, "w": 1.8, "l": 4.0, "first": 0,
        "pose": [[10, 0, -1.7, 0, 0, 0]], "flags": [(1, 0, 0)]}


@pytest.mark.parametrize("broken, error", [
    (lambda s: s.replace("<count>1</count><item_version>1", "<count>2</count><item_version>1"),
     FormatError),
    (lambda s: s.replace("<count>1</count><item_version>2", "<count>3</count><item_version>2"),
     FormatError),
    (lambda s: s.replace("<h>1.5</h>", "<h>nan</h>"), ImpossibleValueError),
    (lambda s: s.replace("<w>1.8</w>", "<w>-1.8</w>"), ImpossibleValueError),
    (lambda s: s.replace("<tx>10.0</tx>", "<tx>1e9</tx>"), ImpossibleValueError),
    (lambda s: s.replace("<tx>10.0</tx>", "<tx>ten</tx>"), FormatError),
    (lambda s: s.replace("<first_frame>0</first_frame>", "<first_frame>-3</first_frame>"),
     ImpossibleValueError),
    (lambda s: s.replace("<state>1</state>", "<state>1.5</state>"), FormatError),
    (lambda s: s.replace("<objectType>Car</objectType>", ""), FormatError),
    (lambda s: s[:-40], FormatError),
])
def test_parser_errors_by_class(broken, error):
    with pytest.raises(error):
        parse_tracklets(broken(tracklet_xml([GOOD])), Path("t.xml"))


# --------------------------------------------------------------------------- keyframes


def _drive(tmp_path: Path, objects: list[dict]) -> Path:
    xml = tmp_path / "tracklet_labels.xml"
    xml.write_text(tracklet_xml(objects))
    _write_calib(tmp_path)
    return xml


def test_keyframes_rate_ignore_rules_and_range(tmp_path):
    n = 25
    car = {"type": "Car", "h": 1.5, "w": 1.8, "l": 4.0, "first": 0,
           "pose": [[22.0, 4.0, -1.65, 0, 0, 0]] * n, "flags": [(1, 0, 0)] * n}
    hidden = dict(car, pose=[[30.0, -4.0, -1.65, 0, 0, 0]] * n, flags=[(1, 2, 0)] * n)
    cut = dict(car, pose=[[30.0, 8.0, -1.65, 0, 0, 0]] * n, flags=[(1, 0, 1)] * n)
    tram = dict(car, type="Tram", pose=[[50.0, 0.0, -1.65, 0, 0, 0]] * n)
    rider = dict(car, type="Cyclist", pose=[[15.0, -2.0, -1.65, 0, 0, 0]] * n)
    xml = _drive(tmp_path, [car, hidden, cut, tram, rider])
    kfs = read_keyframes(xml, fps=10.0, rate_hz=1.0)
    assert [k.frame for k in kfs] == [0, 10, 20] and [k.t_s for k in kfs] == [0.0, 1.0, 2.0]
    boxes = kfs[1].boxes
    assert [(b.category, b.ignore) for b in boxes] == [
        ("car", False), ("car", True), ("car", True), ("tram", True)]
    assert boxes[0].range_m == pytest.approx(20.0)  # the rear face at 22 - 2 m
    assert len(read_keyframes(xml, fps=10.0)) == n  # every frame without a rate
    strict = TrackletKeyframeConfig(ignore_occlusion_from=1)
    assert strict.ignore_occlusion_from == 1 and keyframe_stride(30.0, 1.0) == 30


def test_keyframes_calibration_elsewhere_or_missing(tmp_path):
    xml = tmp_path / "labels" / "tracklet_labels.xml"
    xml.parent.mkdir()
    xml.write_text(tracklet_xml([GOOD]))
    with pytest.raises(MissingInputError):
        read_keyframes(xml, fps=10.0)
    (tmp_path / "calib").mkdir()
    _write_calib(tmp_path / "calib")
    assert read_keyframes(xml, fps=10.0, calib_dir=tmp_path / "calib")[0].boxes
    with pytest.raises(ImpossibleValueError):
        read_keyframes(xml, fps=10.0, calib_dir=tmp_path / "calib", rate_hz=-1.0)


# --------------------------------------------------------------------------- the real drive


def test_real_tracklets_of_kitti_raw_0001(kitti_raw_dir):
    xml = kitti_raw_dir / "tracklet_labels.xml"
    tracklets = read_tracklets(xml)
    types = [t.object_type for t in tracklets]
    assert len(tracklets) == 15 and types.count("Car") == 12 and types.count("Cyclist") == 2
    truth = tracklet_truth(tracklets, calibration_beside(xml), (1242, 374), camera_height_m=1.65,
                           fps=10.0, motion=ego_motion(kitti_raw_dir), n_frames=108)
    cars = truth.object_type == "Car"
    tram = truth.object_type == "Tram"
    # Every car of the drive is parked (the data README), the tram drives at about 9 m/s;
    # parked cars close in at the ego's 10-13 m/s.
    assert truth.parked[cars].all() and not truth.parked[tram].any()
    assert np.nanmedian(truth.speed_mps[cars]) < 0.4
    assert 8.0 < np.nanmedian(truth.speed_mps[tram]) < 10.5
    rate = truth.range_rate_mps[cars & (np.abs(truth.lateral_m) < 12)]
    assert -14 < np.nanmedian(rate) < -10
    # The boxes project into the image where the cars are: in view, below the horizon.
    inview = np.isfinite(truth.box_px[:, 0])
    assert inview.mean() > 0.95
    assert (truth.box_px[inview & cars, 3] > 173).all()
    # 1 Hz keyframes over the drive's 108 frames.
    kfs = read_keyframes(xml, fps=10.0, rate_hz=1.0, image_size_px=(1242, 374))
    assert [k.frame for k in kfs] == list(range(0, 108, 10))
    assert sum(not b.ignore for k in kfs for b in k.boxes) == 20
