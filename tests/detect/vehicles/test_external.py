"""Readers of other tools' boxes (MOT CSV, Scalabel JSON) and of KITTI labels; scoring rule."""

from __future__ import annotations

import json

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vid2sim.base.errors import FormatError, ImpossibleValueError, MissingInputError
from vid2sim.core.records import Detection
from vid2sim.detect.vehicles.external import (
    KittiLabel,
    read_detections,
    read_kitti_tracking_labels,
    score_against_kitti,
)

coord = st.floats(min_value=0, max_value=2000, allow_nan=False).map(lambda v: round(v, 2))
size = st.floats(min_value=1, max_value=500, allow_nan=False).map(lambda v: round(v, 2))
score = st.floats(min_value=0, max_value=1, allow_nan=False).map(lambda v: round(v, 4))
category = st.sampled_from(["car", "truck", "bus", "motorcycle"])
box_rows = st.lists(st.tuples(st.integers(0, 500), coord, coord, size, size, score, category),
                    max_size=30)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=box_rows)
def test_mot_round_trip_with_named_classes(tmp_path, rows):
    path = tmp_path / "det.txt"
    lines = [f"{f + 1},-1,{x},{y},{w},{h},{s},{c}" for f, x, y, w, h, s, c in rows]
    path.write_text("\n".join(lines) + "\n")
    got = read_detections(path)
    expected: dict[int, list[Detection]] = {}
    for f, x, y, w, h, s, c in rows:
        expected.setdefault(f, []).append(Detection((x, y, x + w, y + h), s, c))
    assert got.keys() == expected.keys()
    for f, dets in expected.items():
        assert [d.category for d in got[f]] == [d.category for d in dets]
        for a, b in zip(got[f], dets, strict=True):
            assert a.box_px == pytest.approx(b.box_px)
            assert a.score == pytest.approx(b.score)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=box_rows)
def test_scalabel_round_trip(tmp_path, rows):
    frames: dict[int, list] = {}
    for f, x, y, w, h, s, c in rows:
        frames.setdefault(f, []).append({"id": str(len(frames)), "category": c, "score": s,
                                         "box2d": {"x1": x, "y1": y, "x2": x + w, "y2": y + h}})
    data = [{"name": f"v-{f:07d}.jpg", "videoName": "v", "frameIndex": f, "labels": labels}
            for f, labels in sorted(frames.items(), reverse=True)]
    path = tmp_path / "labels.json"
    path.write_text(json.dumps(data))
    got = read_detections(path)
    assert sorted(got) == sorted(frames)
    for f, labels in frames.items():
        got_flat = [v for d in got[f] for v in d.box_px]
        want_flat = [lab["box2d"][k] for lab in labels for k in ("x1", "y1", "x2", "y2")]
        assert got_flat == pytest.approx(want_flat)
        assert [d.category for d in got[f]] == [lab["category"] for lab in labels]


def test_mot_conventions(tmp_path):
    path = tmp_path / "gt.txt"
    path.write_text(
        "1,1,10,20,30,40,1,3,1.0\n"      # gt: class 3 car, flag 1 -> score 1
        "1,2,50,20,30,40,0,3,1.0\n"      # gt: flag 0 = ignore
        "2,3,10,20,30,40,1,1,0.5\n"      # gt: pedestrian -> dropped
        "3,4,10,20,30,40,1,5,0.9\n"      # gt: motorbike
        "4,-1,5,6,7,8,0.7,-1,-1,-1\n"    # 10-column det file row: car, score 0.7
        "5,-1,5,6,7,8,-1\n")             # score unknown -> 1.0
    got = read_detections(path)
    assert got[0] == [Detection((10.0, 20.0, 40.0, 60.0), 1.0, "car")]
    assert 1 not in got
    assert got[2][0].category == "motorcycle"
    assert got[3] == [Detection((5.0, 6.0, 12.0, 14.0), 0.7, "car")]
    assert got[4][0].score == 1.0


def test_scalabel_object_with_frames_and_non_vehicles(tmp_path):
    path = tmp_path / "bdd.json"
    path.write_text(json.dumps({"frames": [
        {"name": "b.jpg", "labels": [{"category": "pedestrian",
                                      "box2d": {"x1": 0, "y1": 0, "x2": 5, "y2": 5}}]},
        {"name": "a.jpg", "labels": [{"category": "motor",
                                      "box2d": {"x1": 1, "y1": 2, "x2": 3, "y2": 4}},
                                     {"category": "car", "poly2d": []}]},
    ]}))
    got = read_detections(path)
    # no frameIndex: frames are numbered in name order
    assert got == {0: [Detection((1.0, 2.0, 3.0, 4.0), 1.0, "motorcycle")], 1: []}


@pytest.mark.parametrize("content, suffix, error, where", [
    ("0,1,2,3,4,5,0.5\n", ".txt", ImpossibleValueError, "line 1"),  # MOT frames count from 1
    ("1,2,3\n", ".txt", FormatError, "line 1"),  # 3 of at least 6 columns
    ("1,2,a,b,c,d\n", ".csv", FormatError, "line 1"),
    ("{not json", ".json", FormatError, "line 1"),
    ('{"x": 1}', ".json", FormatError, ""),  # neither a list of frames nor {"frames": ...}
])
def test_bad_files_raise_input_error(tmp_path, content, suffix, error, where):
    path = tmp_path / f"bad{suffix}"
    path.write_text(content)
    with pytest.raises(error, match=where):
        read_detections(path)
    with pytest.raises(MissingInputError):
        read_detections(tmp_path / "absent.txt")


def _label(kind, box, trunc=0.0, occ=0):
    return KittiLabel(0, 1, kind, trunc, occ, box, (1.5, 1.6, 4.0), (0.0, 1.6, 20.0))


def test_score_against_kitti_rule():
    labels = [_label("Car", (100, 100, 200, 160)),             # target
              _label("Van", (300, 100, 380, 130)),             # target (h 30)
              _label("Car", (500, 100, 540, 120)),             # too small: not a target
              _label("Car", (600, 100, 700, 160), occ=2),      # occluded: not a target
              _label("DontCare", (800, 100, 900, 150))]
    dets = [Detection((102, 101, 199, 161), 0.9, "car"),     # hits target 1
            Detection((104, 100, 200, 158), 0.8, "car"),     # duplicate -> false
            Detection((501, 100, 541, 121), 0.5, "car"),     # on a small car: not false
            Detection((601, 101, 699, 160), 0.5, "car"),     # on the occluded car: not false
            Detection((820, 110, 860, 140), 0.5, "car"),     # inside DontCare: not false
            Detection((1000, 100, 1050, 140), 0.5, "car")]   # nothing there -> false
    counts = score_against_kitti(dets, labels)
    assert (counts.n_targets, counts.n_found, counts.n_detections, counts.n_false) == (2, 1, 6, 2)
    assert counts.recall == 0.5
    assert counts.precision == pytest.approx(4 / 6)


def test_read_kitti_labels(kitti_tracking_dir):
    labels = read_kitti_tracking_labels(kitti_tracking_dir / "label_02" / "0001.txt")
    frame10 = labels[10]
    car2 = next(lab for lab in frame10 if lab.track_id == 2)
    assert car2.type == "Car" and car2.occluded == 0
    assert car2.box_px == pytest.approx((780.042083, 178.652771, 1016.857010, 335.097849))
    assert sum(lab.type == "DontCare" for lab in frame10) == 7


def test_own_detections_csv_reads_back(tmp_path):
    from vid2sim.core.records import TrackedBox
    from vid2sim.core.tables import write_detections_csv

    rows = [TrackedBox(0, 0.0, 1, "car", 0.9, 1.0, 2.0, 30.0, 40.0),
            TrackedBox(0, 0.0, 2, "bus", 0.5, 50.0, 2.0, 90.0, 40.0),
            TrackedBox(4, 0.4, 1, "car", 0.8, 5.0, 2.0, 35.0, 40.0)]
    path = tmp_path / "detections.csv"
    write_detections_csv(rows, path)
    got = read_detections(path)
    assert got == {0: [Detection((1.0, 2.0, 30.0, 40.0), 0.9, "car"),
                       Detection((50.0, 2.0, 90.0, 40.0), 0.5, "bus")],
                   4: [Detection((5.0, 2.0, 35.0, 40.0), 0.8, "car")]}


# --------------------------------------------------------------------------- damaged files


def _samples() -> dict[str, bytes]:
    own = ("frame,t_s,track_id,category,score,x1,y1,x2,y2\n"
           "0,0.0,1,car,0.9,10.0,20.0,50.0,60.0\n1,0.1,1,car,0.8,12.0,20.0,52.0,60.0\n"
           "1,0.1,2,truck,0.7,100.0,20.0,180.0,90.0\n")
    mot = "1,1,10,20,30,40,0.9,car\n2,1,12,20,30,40,0.8,car\n2,2,100,20,80,70,0.7,truck\n"
    scalabel = json.dumps([{"name": f"f{i}.jpg", "frameIndex": i, "labels": [
        {"category": "car", "score": 0.9,
         "box2d": {"x1": 10.0 + i, "y1": 20.0, "x2": 50.0 + i, "y2": 60.0}}]} for i in range(3)])
    return {"detections.csv": own.encode(), "det.txt": mot.encode(),
            "labels.json": scalabel.encode()}


@pytest.mark.parametrize("name", ["detections.csv", "det.txt", "labels.json"])
def test_detection_file_damage_gives_input_error_only(tmp_path, name):
    import math

    from tests.damage import FUZZ, damaged, input_error_or_result

    @FUZZ
    @given(data=damaged(_samples()[name]))
    def check(data):
        path = tmp_path / name
        path.write_bytes(data)
        got = input_error_or_result(read_detections, path)
        if isinstance(got, dict):  # what reads is usable: finite boxes with an area
            for frame, dets in got.items():
                assert frame >= 0
                for d in dets:
                    x1, y1, x2, y2 = d.box_px
                    assert all(math.isfinite(v) for v in d.box_px) and x2 > x1 and y2 > y1
                    assert 0.0 <= d.score <= 1.0

    check()


@pytest.mark.parametrize("content,suffix,error,where", [
    ("1,1,nan,20,30,40,0.9,car\n", ".txt", ImpossibleValueError, "line 1"),
    ("1,1,10,20,inf,40,0.9,car\n", ".txt", ImpossibleValueError, "line 1"),
    ("1,1,10,20,0,40,0.9,car\n", ".txt", ImpossibleValueError, "line 1"),  # no width
    ("1,1,10,20,30,-4,0.9,car\n", ".txt", ImpossibleValueError, "line 1"),  # negative height
    ("1e300,1,10,20,30,40,0.9,car\n", ".txt", ImpossibleValueError, "line 1"),  # no frame's
    ("frame,t_s,track_id,category,score,x1,y1,x2,y2\n0,0,1,car,nan,1,2,3,4\n", ".csv",
     ImpossibleValueError, "line 2"),
    (('[{"frameIndex": 0, "labels": [{"category": "car", "box2d": '
     '{"x1": 5, "y1": 5, "x2": 5, "y2": 9}}]}]'), ".json", ImpossibleValueError, "frame 0"),
    ('[{"frameIndex": "x", "labels": []}]', ".json", FormatError, "frame 0"),
    ("[" * 100_000 + "]" * 100_000, ".json", FormatError, ""),  # nested too deeply to parse
])
def test_non_finite_and_degenerate_boxes_are_input_errors(tmp_path, content, suffix, error,
                                                          where):
    path = tmp_path / f"bad{suffix}"
    path.write_text(content)
    with pytest.raises(error, match=where):
        read_detections(path)


def test_binary_detections_are_an_input_error(tmp_path):
    path = tmp_path / "det.csv"
    path.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(FormatError):  # binary, not UTF-8 text
        read_detections(path)
