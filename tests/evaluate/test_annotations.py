"""Annotation readers: Scalabel/BDD100K JSON, KITTI label_02, CVAT for video XML."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vid2sim.base.errors import (
    FormatError,
    ImpossibleValueError,
    InconsistentInputError,
    InputError,
    MissingInputError,
)
from vid2sim.evaluate.annotations import read_keyframes

KITTI_LINES = """\
10 -1 DontCare -1 -1 -10.000000 621.27 173.78 641.18 190.77 -1000 -1000 -1000 -10 -1 -1 -1
10 2 Car 0 0 -1.838107 780.04 178.65 1016.86 335.10 1.41 1.57 3.16 2.94 1.49 8.14 -1.503805
10 7 Pedestrian 0 0 0.1 100 100 120 160 1.7 0.6 0.9 -2.0 1.5 9.0 0.2
15 3 Van 1 0 2.26 0.0 214.97 197.03 374.0 1.53 1.56 3.58 -5.99 2.04 7.19 1.587202
15 4 Tram 0 0 0.3 400 100 700 300 3.5 2.5 20.0 1.0 1.6 30.0 -1.57
20 5 Truck 0 1 -1.65 658.72 177.80 714.33 219.95 3.1 2.5 8.0 2.87 1.72 28.09 -1.570796
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# --------------------------------------------------------------------------- KITTI


def test_kitti_frames_classes_ignore_and_range(tmp_path):
    p = write(tmp_path, "0001.txt", KITTI_LINES)
    kfs = read_keyframes(p)  # KITTI's own 10 Hz
    assert [(k.frame, k.t_s) for k in kfs] == [(10, 1.0), (15, 1.5), (20, 2.0)]
    f10 = kfs[0].boxes
    assert [(b.category, b.ignore, b.id) for b in f10] == [("dontcare", True, None),
                                                           ("car", False, "2")]
    car = f10[1]
    assert car.box_px == pytest.approx((780.04, 178.65, 1016.86, 335.10))
    # near face: Z - (l/2 |sin ry| + w/2 |cos ry|)
    expect = 8.14 - (3.16 / 2 * abs(math.sin(-1.503805)) + 1.57 / 2 * abs(math.cos(-1.503805)))
    assert car.range_m == pytest.approx(expect)
    assert f10[0].range_m is None
    f15 = {b.category: b for b in kfs[1].boxes}
    assert f15["car"].ignore is False  # Van counts as a car
    assert f15["tram"].ignore is True
    assert kfs[2].boxes[0].category == "truck"


def test_kitti_with_image_folder_names_maps_to_folder_position(tmp_path):
    p = write(tmp_path, "0001.txt", KITTI_LINES)
    names = ["000010.png", "000015.png", "000020.png"]
    kfs = read_keyframes(p, fps=2.0, frame_names=names)
    assert [(k.frame, k.t_s, k.name) for k in kfs] == [(0, 0.0, "000010"), (1, 0.5, "000015"),
                                                      (2, 1.0, "000020")]
    # frames without an image are dropped, not shifted
    kfs = read_keyframes(p, fps=2.0, frame_names=["000015.png"])
    assert [(k.frame, k.name) for k in kfs] == [(0, "000015")]
    with pytest.raises(InconsistentInputError):  # labels of another video's frames
        read_keyframes(p, fps=2.0, frame_names=["000099.png"])


@pytest.mark.parametrize("text, error, where", [
    ("10 2 Car 0 0 -1.8 780 178 1016\n", FormatError, "line 1"),  # 9 of 17 fields
    ("10 x Car 0 0 -1.8 780 178 1016 335 1.4 1.6 3.2 2.9 1.5 8.1 -1.5\n", FormatError, "line 1"),
    ("10 2 Car 0 0 -1.8 780 178 700 335 1.4 1.6 3.2 2.9 1.5 8.1 -1.5\n", ImpossibleValueError,
     "line 1"),  # x2 < x1
    ("10 2 Car 0 0 -1.8 780 178 nan 335 1.4 1.6 3.2 2.9 1.5 8.1 -1.5\n", ImpossibleValueError,
     "line 1"),
    ("10 7 Pedestrian 0 0 0.1 100 100 120 160 1.7 0.6 0.9 -2.0 1.5 9.0 0.2\n", FormatError,
     ""),  # no vehicle labelled
])
def test_kitti_malformed(tmp_path, text, error, where):
    with pytest.raises(error, match=where):
        read_keyframes(write(tmp_path, "bad.txt", text))


# --------------------------------------------------------------------------- Scalabel


def test_scalabel_index_timestamp_and_name(tmp_path):
    frames = [
        {"name": "v-0003.jpg", "index": 3, "labels": [
            {"id": "7", "category": "car", "box2d": {"x1": 1, "y1": 2, "x2": 30, "y2": 40}},
            {"id": "8", "category": "pedestrian", "box2d": {"x1": 1, "y1": 2, "x2": 3, "y2": 4}},
            {"id": "9", "category": "bus", "attributes": {"crowd": True},
             "box2d": {"x1": 5, "y1": 5, "x2": 9, "y2": 9}},
            {"id": "10", "category": "car", "poly2d": [[0, 0], [1, 1]]}]},
        {"name": "v-0000.jpg", "index": 0, "labels": None},
    ]
    p = write(tmp_path, "a.json", json.dumps(frames))
    kfs = read_keyframes(p, fps=5.0)
    assert [(k.frame, k.t_s, k.name) for k in kfs] == [(0, 0.0, "v-0000.jpg"),
                                                      (3, 0.6, "v-0003.jpg")]
    assert [(b.id, b.category, b.ignore) for b in kfs[1].boxes] == [("7", "car", False),
                                                                    ("9", "bus", True)]
    assert read_keyframes(p, fps=5.0, labelled_only=True)[0].name == "v-0003.jpg"
    # {"frames": [...]} and timestamps in ms relative to the first
    ts = {"frames": [{"name": "b", "timestamp": 1_000_500, "labels": []},
                     {"name": "a", "timestamp": 1_000_000, "labels": []}]}
    kfs = read_keyframes(write(tmp_path, "b.json", json.dumps(ts)), fps=10.0)
    assert [(k.name, k.t_s, k.frame) for k in kfs] == [("a", 0.0, 0), ("b", 0.5, 5)]
    # names matched against an image folder
    by_name = [{"name": "img_b.png", "labels": []}, {"name": "nothere.png", "labels": []}]
    kfs = read_keyframes(write(tmp_path, "c.json", json.dumps(by_name)), fps=2.0,
                         frame_names=["img_a.png", "img_b.png"])
    assert [(k.name, k.frame, k.t_s) for k in kfs] == [("img_b.png", 1, 0.5)]


@pytest.mark.parametrize("text, error, where", [
    ("[{\"index\": 1, \"labels\": []}", FormatError, "line 1"),  # JSON cut off
    ("{\"images\": []}", FormatError, ""),  # no 'frames'
    ("[{\"index\": 1, \"labels\": []}]", MissingInputError, "--fps"),  # indices need a rate
    ("[{\"index\": -1, \"labels\": []}]", FormatError, r"frames\[0\]\.index"),
    ("[{\"labels\": []}]", FormatError, r"frames\[0\]"),  # no name, index or timestamp
    ("[{\"name\": \"abc.jpg\", \"labels\": []}]", FormatError, "abc.jpg"),
    ("[{\"index\": 1, \"labels\": [{\"category\": \"car\", \"box2d\": {\"x1\": 1}}]}]",
     FormatError, r"frames\[0\]\.labels\[0\]\.box2d"),
    (("[{\"index\": 1, \"labels\": [{\"category\": \"car\", \"box2d\": "
     "{\"x1\": \"a\", \"y1\": 0, \"x2\": 1, \"y2\": 1}}]}]"), FormatError,
     r"frames\[0\]\.labels\[0\]\.box2d"),
    ("[]", FormatError, ""),  # no frames
    ("hello", FormatError, ""),  # no known annotation format
])
def test_scalabel_malformed(tmp_path, text, error, where):
    fps = None if where == "--fps" else 10.0
    with pytest.raises(error, match=where):
        read_keyframes(write(tmp_path, "bad.json", text), fps=fps)


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(MissingInputError):
        read_keyframes(tmp_path / "none.json")
    with pytest.raises(MissingInputError):  # a folder, not a file
        read_keyframes(tmp_path)


# --------------------------------------------------------------------------- CVAT


CVAT = """<?xml version="1.0" encoding="utf-8"?>
<annotations>
  <version>1.1</version>
  <meta><task><size>30</size><mode>interpolation</mode></task></meta>
  <track id="0" label="car" source="manual">
    <box frame="0" outside="0" occluded="0" keyframe="1" xtl="10" ytl="20" xbr="50" ybr="60" z_order="0"/>
    <box frame="1" outside="0" occluded="0" keyframe="0" xtl="12" ytl="20" xbr="52" ybr="60" z_order="0"/>
    <box frame="5" outside="0" occluded="0" keyframe="1" xtl="20" ytl="20" xbr="60" ybr="60" z_order="0"/>
    <box frame="6" outside="1" occluded="0" keyframe="1" xtl="20" ytl="20" xbr="60" ybr="60" z_order="0"/>
  </track>
  <track id="1" label="truck" source="manual">
    <box frame="5" outside="0" occluded="1" keyframe="0" xtl="100" ytl="10" xbr="180" ybr="90" z_order="0"/>
  </track>
  <track id="2" label="person" source="manual">
    <box frame="0" outside="0" occluded="0" keyframe="1" xtl="1" ytl="1" xbr="5" ybr="9" z_order="0"/>
  </track>
</annotations>
"""


def test_cvat_video_keyframes(tmp_path):
    kfs = read_keyframes(write(tmp_path, "a.xml", CVAT), fps=10.0)
    # frame 1 holds only an interpolated box, frame 6 only the car leaving: not keyframes
    assert [k.frame for k in kfs] == [0, 5]
    assert [(b.id, b.category) for b in kfs[0].boxes] == [("0", "car")]
    assert [(b.id, b.category, b.box_px) for b in kfs[1].boxes] == [
        ("0", "car", (20.0, 20.0, 60.0, 60.0)), ("1", "truck", (100.0, 10.0, 180.0, 90.0))]
    assert kfs[1].t_s == pytest.approx(0.5)


@pytest.mark.parametrize("text, where", [
    (("<annotations><track label='car'><box frame='0' xtl='1' ytl='1' xbr='2'/></track>"
     "</annotations>"), "ybr"),  # the attribute that is missing
    (("<annotations><track label='car'><box frame='a' xtl='1' ytl='1' xbr='2' ybr='3'/>"
     "</track></annotations>"), "track 0 box 0"),  # frame='a'
    ("<annotations><track label='car'>", "line 1"),  # XML cut off
    ("<root/>", "<root>"),
    ("<annotations><version>1.1</version></annotations>", ""),  # no <track> or <image>
])
def test_cvat_malformed(tmp_path, text, where):
    with pytest.raises(FormatError, match=where):
        read_keyframes(write(tmp_path, "bad.xml", text), fps=10.0)


# --------------------------------------------------------------------------- round trips


box_st = st.tuples(st.integers(0, 1000), st.integers(0, 300), st.integers(1, 200),
                   st.integers(1, 150)).map(lambda b: (float(b[0]), float(b[1]),
                                                       float(b[0] + b[2]), float(b[1] + b[3])))
frames_st = st.dictionaries(st.integers(0, 500), st.lists(
    st.tuples(box_st, st.sampled_from(["car", "truck", "bus"])), min_size=1, max_size=5),
    min_size=1, max_size=6)


@given(frames_st)
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_round_trip_all_formats(tmp_path, frames):
    expect = {f: sorted((b, c) for b, c in boxes) for f, boxes in frames.items()}
    scal = [{"name": f"f{f:05d}.jpg", "index": f, "labels": [
        {"id": str(i), "category": c, "box2d": dict(zip(("x1", "y1", "x2", "y2"), b, strict=True))}
        for i, (b, c) in enumerate(boxes)]} for f, boxes in frames.items()]
    kitti_cls = {"car": "Car", "truck": "Truck", "bus": "Truck"}
    kitti = "".join(f"{f} {i} {kitti_cls[c]} 0 0 0 {b[0]} {b[1]} {b[2]} {b[3]} 1.5 1.8 4 0 1.6 "
                    f"20 -1.57\n" for f, boxes in frames.items() for i, (b, c) in enumerate(boxes))
    cvat = "<annotations>" + "".join(
        f"<track id='{f}_{i}' label='{c}'><box frame='{f}' outside='0' keyframe='1' "
        f"xtl='{b[0]}' ytl='{b[1]}' xbr='{b[2]}' ybr='{b[3]}'/></track>"
        for f, boxes in frames.items() for i, (b, c) in enumerate(boxes)) + "</annotations>"
    for name, text in (("a.json", json.dumps(scal)), ("a.txt", kitti), ("a.xml", cvat)):
        kfs = read_keyframes(write(tmp_path, name, text), fps=4.0)
        assert [k.frame for k in kfs] == sorted(frames)
        for k in kfs:
            assert k.t_s == pytest.approx(k.frame / 4.0)
            got = sorted((b.box_px, b.category) for b in k.boxes)
            want = expect[k.frame] if name != "a.txt" else sorted(
                (b, "car" if c == "car" else "truck") for b, c in frames[k.frame])
            assert got == want


# --------------------------------------------------------------------------- real data


@pytest.mark.parametrize("seq, numbers", [("0001", (10, 15, 20)), ("0016", (2, 7, 12))])
def test_kitti_tracking_labelled_frames(kitti_tracking_dir, seq, numbers):
    folder = kitti_tracking_dir / "image_02" / seq
    names = sorted(p.name for p in folder.iterdir())
    assert names == [f"{n:06d}.png" for n in numbers]
    kfs = read_keyframes(kitti_tracking_dir / "label_02" / f"{seq}.txt", fps=2.0,
                         frame_names=names)
    assert [(k.frame, k.t_s, k.name) for k in kfs] == [
        (i, i * 0.5, f"{n:06d}") for i, n in enumerate(numbers)]
    cars = [b for k in kfs for b in k.boxes if not b.ignore]
    assert cars and all(b.range_m is not None and -1.0 < b.range_m < 80.0 for b in cars)
    assert all(b.category in ("car", "truck") for b in cars)
    # every DontCare row became an ignore region
    text = (kitti_tracking_dir / "label_02" / f"{seq}.txt").read_text()
    n_dontcare = sum(1 for line in text.splitlines()
                     if line.split()[2] == "DontCare" and int(line.split()[0]) in numbers)
    assert sum(1 for k in kfs for b in k.boxes if b.category == "dontcare") == n_dontcare


# --------------------------------------------------------------------------- robustness


VALID_SCALABEL = json.dumps([{"name": "a.jpg", "index": 2, "labels": [
    {"id": "1", "category": "car", "attributes": {"crowd": False},
     "box2d": {"x1": 1.5, "y1": 2, "x2": 30, "y2": 40}}]}])


@given(st.sampled_from([KITTI_LINES, VALID_SCALABEL, CVAT]), st.integers(0, 2000),
       st.text(max_size=8))
@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_damaged_files_give_input_errors_only(tmp_path, text, cut, junk):
    """A file truncated anywhere, with junk appended, is read or refused with InputError;
    never another exception."""
    p = write(tmp_path, "damaged", text[:cut] + junk)
    try:
        kfs = read_keyframes(p, fps=10.0)
    except InputError:
        return
    for k in kfs:
        assert k.t_s >= 0 and all(b.box_px[0] <= b.box_px[2] for b in k.boxes)
