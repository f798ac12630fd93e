"""tracks.csv: the lane column, its round trip, and files written before it existed."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.base.errors import FormatError
from vid2sim.core.lead import MAX_RELATIVE_LANE
from vid2sim.core.records import RangedBox
from vid2sim.core.tables import TRACKS_CSV_COLUMNS, read_tracks_csv, write_tracks_csv


def _box(frame: int, tid: int, lane: int | None, range_m: float = 20.0) -> RangedBox:
    return RangedBox(frame, frame / 10, tid, "car", 0.9, 1.0, 2.0, 30.0, 40.0, range_m=range_m,
                     lateral_m=0.5, range_rate_mps=-1.0, range_std_m=0.4, is_lead=lane == 0,
                     lane=lane)


def test_lane_column_is_relative_to_the_ego_lane_and_empty_where_unknown(tmp_path):
    boxes = [_box(0, 1, 0), _box(0, 2, 1), _box(0, 3, -2), _box(1, 1, None)]
    path = tmp_path / "tracks.csv"
    write_tracks_csv(boxes, path)
    lines = path.read_text().splitlines()
    assert lines[0].split(",") == list(TRACKS_CSV_COLUMNS) and lines[0].endswith(",lane")
    assert [ln.rsplit(",", 1)[1] for ln in lines[1:]] == ["0", "1", "-2", ""]
    assert [b.lane for b in read_tracks_csv(path)] == [0, 1, -2, None]


def test_a_file_without_the_lane_column_still_reads(tmp_path):
    path = tmp_path / "old.csv"
    path.write_text("frame,t_s,track_id,category,score,x1,y1,x2,y2,range_m,lateral_m,"
                    "range_rate_mps,range_std_m,is_lead\n"
                    "3,0.3000,7,car,0.900,1.0,2.0,30.0,40.0,20.00,0.50,-1.00,0.40,1\n")
    (b,) = read_tracks_csv(path)
    assert (b.frame, b.track_id, b.is_lead, b.lane) == (3, 7, True, None)


@pytest.mark.parametrize("cell", ["x", "1.5", "17", "-40"])
def test_a_bad_lane_names_the_line(tmp_path, cell):
    path = tmp_path / "bad.csv"
    write_tracks_csv([_box(0, 1, 0)], path)
    text = path.read_text().splitlines()
    text[1] = text[1].rsplit(",", 1)[0] + "," + cell
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(FormatError, match="line 2"):
        read_tracks_csv(path)


@settings(max_examples=40, deadline=None)
@given(lanes=st.lists(st.one_of(st.none(), st.integers(-MAX_RELATIVE_LANE, MAX_RELATIVE_LANE)),
                      min_size=1, max_size=20),
       ranges=st.lists(st.one_of(st.floats(0.5, 150.0), st.just(math.nan)), min_size=20,
                       max_size=20))
def test_round_trip_keeps_every_lane(tmp_path_factory, lanes, ranges):
    boxes = [_box(i, i + 1, k, ranges[i]) for i, k in enumerate(lanes)]
    path = tmp_path_factory.mktemp("t") / "tracks.csv"
    write_tracks_csv(boxes, path)
    back = read_tracks_csv(path)
    assert [b.lane for b in back] == lanes
    for a, b in zip(back, boxes, strict=True):
        assert (math.isnan(a.range_m) and math.isnan(b.range_m)) or \
            a.range_m == pytest.approx(b.range_m, abs=0.006)
