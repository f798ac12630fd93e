"""End-to-end builds: the demo sample (synthetic truth) and the real KITTI material."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from vid2sim.app.build import build
from vid2sim.app.demo import run_demo
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.cli import main
from vid2sim.core import scenario as scenario_io
from vid2sim.core.enu import EnuFrame
from vid2sim.core.lanelayout import BACKWARD, DRIVING, FORWARD, PARKING
from vid2sim.core.polyline import signed_offsets
from vid2sim.evaluate.lane_checks import actor_enters_lane_on_road_s, ego_cross_error, summary
from vid2sim.samples.demo_truth import truth_scenario

QUIET = Settings(progress=False, allow_download=False)

CONTRACT_KEYS = {"keyframes", "tp", "fp", "fn", "precision", "recall", "f1", "mean_iou",
                 "per_keyframe"}


@pytest.fixture(scope="module")
def demo_result(tmp_path_factory):
    """The demo run without detector weights (the sample's noisy imported detections)."""
    out = tmp_path_factory.mktemp("demo")
    result = run_demo(out, force_detections=True, settings=QUIET)
    return out, result


def test_demo_without_weights_reaches_the_keyframe_bar(demo_result):
    out, _ = demo_result
    metrics = json.loads((out / "build" / "metrics.json").read_text())
    assert CONTRACT_KEYS <= metrics.keys()
    print(f"demo (imported detections): P {metrics['precision']:.3f} R {metrics['recall']:.3f} "
          f"F1 {metrics['f1']:.3f} mean IoU {metrics['mean_iou']:.3f}")
    # Issue 7 bar: keyframe F1 >= 0.9 and mean IoU >= 0.7 on the demo sample without weights.
    assert metrics["f1"] >= 0.9
    assert metrics["mean_iou"] >= 0.7
    assert metrics["keyframes"] == len(metrics["per_keyframe"]) > 10


def test_demo_writes_every_output_and_a_valid_scenario(demo_result):
    out, result = demo_result
    build_dir = out / "build"
    for name in ("scenario.json", "scenario.xosc", "road.xodr", "tracks.csv", "report.html",
                 "metrics.json"):
        assert (build_dir / name).stat().st_size > 0, name
    scen = scenario_io.load(build_dir / "scenario.json")
    assert scen.roads and scen.roads[0].source == "osm"
    assert scen.actors, "the demo has a lead, a cut-in and oncoming cars"
    # The scenario's clock is the video's: the ego covers the 24 s clip.
    assert scen.duration_s == pytest.approx(23.9, abs=0.3)
    header = (build_dir / "tracks.csv").read_text().splitlines()[0]
    assert header == ("frame,t_s,track_id,category,score,x1,y1,x2,y2,range_m,lateral_m,"
                      "range_rate_mps,range_std_m,is_lead,lane")
    # No staging folders are left beside the output.
    assert not [p for p in out.iterdir() if p.name.startswith(".build.")]
    assert result.lead_share > 0.5


def test_same_inputs_give_byte_identical_scenarios(demo_result, tmp_path):
    out, _ = demo_result
    sample = out / "sample"
    from vid2sim.samples.demo_sample import helsinki_pbf_path

    video = sample / "demo.mp4"
    if not video.exists():  # the sample falls back to MJPG where mp4v is missing
        video = sample / "demo.avi"
    build(Inputs(video=video, gps=sample / "demo.gpx", map=helsinki_pbf_path(),
                 camera=sample / "camera.yaml", detections=sample / "detections.txt",
                 keyframes=sample / "keyframes.json"), tmp_path / "again", QUIET)
    for name in ("scenario.json", "scenario.xosc", "road.xodr", "tracks.csv"):
        first = (out / "build" / name).read_bytes()
        again = (tmp_path / "again" / name).read_bytes()
        assert first == again, name
    # metrics.json names where its inputs are (the two builds have different folders).
    first, again = (json.loads((d / "metrics.json").read_text())
                    for d in (out / "build", tmp_path / "again"))
    first.pop("inputs")
    again.pop("inputs")
    assert first == again


def test_build_without_gps_is_camera_relative(demo_result, tmp_path):
    out, _ = demo_result
    sample = out / "sample"
    video = sample / "demo.mp4" if (sample / "demo.mp4").exists() else sample / "demo.avi"
    result = build(Inputs(video=video, camera=sample / "camera.yaml",
                          detections=sample / "detections.txt"), tmp_path / "rel", QUIET)
    scen = scenario_io.load(result.files["scenario"])
    assert all(p == 0 for p in scen.ego.trajectory.speed)
    assert any("no GPS" in a for a in scen.source.assumptions)
    assert scen.roads[0].source != "osm"


def test_bad_input_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["build", str(tmp_path / "missing.mp4"), "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("error: ") and "missing.mp4" in err[0]
    assert not out.exists()


def test_broken_gps_fails_before_any_output(demo_result, tmp_path, capsys):
    out_demo, _ = demo_result
    sample = out_demo / "sample"
    video = sample / "demo.mp4" if (sample / "demo.mp4").exists() else sample / "demo.avi"
    gps = tmp_path / "broken.gpx"
    gps.write_text("<gpx><trk><trkseg><trkpt lat='91' lon='0'></trkpt></trkseg></trk>")
    out = tmp_path / "out"
    code = main(["build", str(video), "--gps", str(gps), "--detections",
                 str(sample / "detections.txt"), "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "broken.gpx" in err[0]
    assert not out.exists()


# --------------------------------------------------------------------------- real data


def test_kitti_raw_build_falls_back_to_a_trajectory_road(kitti_raw_dir, model_dir, tmp_path):
    settings = Settings(detector=DetectorSettings(model_dir=model_dir, detect_every=2),
                        allow_download=False, progress=False)
    result = build(Inputs(video=kitti_raw_dir / "video.mp4", gps=kitti_raw_dir,
                          camera=kitti_raw_dir / "camera.yaml"), tmp_path / "k", settings)
    scen = scenario_io.load(result.files["scenario"])
    assert scen.roads[0].source == "trajectory"
    # KITTI's camera clock gives the video-GPS alignment; the drive is ~10.7 s at ~10 m/s.
    assert scen.duration_s == pytest.approx(10.7, abs=0.3)
    assert 80 < result.distance_m < 130
    assert len(scen.actors) >= 3, "parked cars line the street"


@pytest.mark.parametrize("seq", ["0001", "0016"])
def test_kitti_tracking_keyframes_are_scored(kitti_tracking_dir, model_dir, tmp_path, seq):
    """Issue 7: the labelled KITTI frames as a 2 fps video without GPS; figures printed."""
    settings = Settings(detector=DetectorSettings(model_dir=model_dir), allow_download=False,
                        progress=False)
    result = build(Inputs(video=kitti_tracking_dir / "image_02" / seq,
                          camera=kitti_tracking_dir / "calib" / f"{seq}.txt",
                          keyframes=kitti_tracking_dir / "label_02" / f"{seq}.txt", fps=2.0),
                   tmp_path / seq, settings)
    metrics = json.loads(Path(result.files["metrics"]).read_text())
    assert CONTRACT_KEYS <= metrics.keys()
    assert metrics["keyframes"] == 3
    print(f"KITTI {seq}: P {metrics['precision']:.3f} R {metrics['recall']:.3f} "
          f"F1 {metrics['f1']:.3f} mean IoU {metrics['mean_iou']:.3f} "
          f"range error {metrics.get('range_error')}")
    assert metrics["tp"] + metrics["fn"] > 0


def test_scenario_does_not_depend_on_where_the_inputs_are(demo_result, tmp_path, monkeypatch):
    # The same input files, given by absolute path from one folder and by relative path from
    # a copy elsewhere, must give the same scenario.json bytes (the README's promise).
    import shutil

    out, _ = demo_result
    sample = out / "sample"
    video = sample / "demo.mp4" if (sample / "demo.mp4").exists() else sample / "demo.avi"
    names = (video.name, "demo.gpx", "camera.yaml", "detections.txt")
    copy = tmp_path / "elsewhere" / "inputs"
    copy.mkdir(parents=True)
    for name in names:
        shutil.copy(sample / name, copy / name)

    def run(folder: Path, out_dir: Path) -> bytes:
        v, g, c, d = (folder / n for n in names)
        build(Inputs(video=v, gps=g, camera=c, detections=d), out_dir, QUIET)
        return (out_dir / "scenario.json").read_bytes()

    absolute = run(sample.resolve(), tmp_path / "a")
    monkeypatch.chdir(tmp_path / "elsewhere")
    relative = run(Path("inputs"), tmp_path / "b")
    assert absolute == relative


def test_demo_ego_sits_in_its_lane(demo_result):
    """Issue 19: the lane markings place the scenario's ego across the road. Acceptance:
    lateral error against the true ego path <= 0.3 m RMS and <= 0.6 m p95 (the smoothed GPS
    alone: 1.5 m RMS, 2.5 m p95); the tighter bounds are regression floors a little above
    what the method achieves (0.11 m RMS, 0.28 m p95 at a2556fa; figures by regime in
    benchmarks/bench_lanes.py)."""
    out, result = demo_result
    built = scenario_io.load(out / "build" / "scenario.json")
    truth = truth_scenario(out / "sample" / "truth.json")
    _, cross = ego_cross_error(built.origin, built.ego.trajectory, truth)
    s = summary(cross)
    print(f"demo ego lateral error: RMS {s['rms_m']:.3f} p95 {s['p95_m']:.3f} bias "
          f"{s['bias_m']:+.3f} m")
    assert s["n"] > 200
    assert s["rms_m"] <= 0.3 and s["p95_m"] <= 0.6
    assert s["rms_m"] <= 0.15 and s["p95_m"] <= 0.35 and abs(s["bias_m"]) <= 0.08
    lateral = result.lateral
    assert lateral.source == "lane markings + map"
    assert (lateral.lane == 0).all() and lateral.lane_changes == []  # the ego holds its lane
    assert lateral.lanes.detection_rate >= 0.8


def test_demo_street_has_its_lanes_and_parking_strip(demo_result):
    """The rendered demo street (one 3.5 m lane each way, a 2.5 m parking strip on the right
    with three parked cars; an OSM map): the built road's cross-section and the parked cars
    against the truth."""
    out, _ = demo_result
    built = scenario_io.load(out / "build" / "scenario.json")
    truth = truth_scenario(out / "sample" / "truth.json")
    road = built.roads[0]
    sec = road.layout()
    kinds = [(lane.type, lane.direction) for lane in sec.lanes]
    assert kinds == [(PARKING, FORWARD), (DRIVING, FORWARD), (DRIVING, BACKWARD)]
    for k in (1, 2):
        assert abs(sec.lanes[k].width_m - 3.5) <= 0.5
    assert 2.0 <= sec.lanes[0].width_m <= 3.5
    # every true parked car stands in the built parking lane (its truth position measured
    # against the built road)
    e = sec.edges_m
    parked = [a for a in truth.actors if a.id.startswith("parked")]
    assert len(parked) == 3
    for a in parked:  # truth ENU -> WGS-84 -> the build's ENU (a build picks its origin)
        lat, lon, _ = EnuFrame(truth.origin).to_geodetic(
            np.column_stack((a.trajectory.x, a.trajectory.y)))
        _, d = signed_offsets(road.centerline, EnuFrame(built.origin).to_enu(lat, lon))
        assert e[0] - 0.3 <= float(np.median(d)) <= e[1] + 0.3, a.id


def test_demo_cut_in_event_at_the_true_moment(demo_result):
    """Issue 19: the demo's cut-in car (overtakes on the left and merges in front) gives a
    ``cut_in`` event from lane +1 to 0 within 0.5 s of the moment its centre crosses the
    ego lane's left boundary (the centre line of the true two-lane road; measured -0.13 s),
    and nothing else in the demo changes lanes."""
    out, result = demo_result
    built = scenario_io.load(out / "build" / "scenario.json")
    truth = truth_scenario(out / "sample" / "truth.json")
    road = json.loads((out / "sample" / "truth.json").read_text())["road"]
    assert road["lanes"] == 2  # one lane each way: the ego lane is right of the centre line
    t_true = actor_enters_lane_on_road_s(truth, "cutin", 0.0, -road["lane_width_m"])
    assert t_true is not None
    cut_ins = [e for e in built.events if e.type == "cut_in"]
    print(f"demo cut-in: truth {t_true:.2f} s, events {built.events}")
    assert len(cut_ins) == 1 and (cut_ins[0].from_lane, cut_ins[0].to_lane) == (1, 0)
    assert abs(cut_ins[0].t_s - t_true) <= 0.5
    assert built.events == cut_ins  # nothing else
    assert [(e.type, e.actor) for e in result.events] == [("cut_in", cut_ins[0].actor)]
    assert result.events[0].t_s == pytest.approx(cut_ins[0].t_s, abs=1e-3)  # JSON rounding
