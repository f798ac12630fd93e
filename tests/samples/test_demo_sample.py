"""The demo sample: route on the real map, truth, GPS noise, annotations, detections, determinism."""

from __future__ import annotations

import itertools
import json
import math
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest

from vid2sim.core.camera import load_camera
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import Origin
from vid2sim.samples.demo_sample import (
    EGO_LANE_OFFSET_M,
    GARMIN_TPX_NS,
    KEYFRAME_OFFSET_S,
    VIDEO_START_UTC,
    DemoSample,
    compare_to_truth,
    demo_camera,
    generate_demo_sample,
    gps_noise_enu,
    load_route,
    truth_scenario,
)


@pytest.fixture(scope="module")
def route():
    return load_route()


@pytest.fixture(scope="module")
def sample(route, tmp_path_factory) -> DemoSample:
    return generate_demo_sample(tmp_path_factory.mktemp("demo"), route=route)


@pytest.fixture(scope="module")
def truth(sample) -> dict:
    return json.loads(sample.truth.read_text())


def _traj(truth: dict, actor_id: str) -> dict[str, np.ndarray]:
    points = truth["ego"]["trajectory"] if actor_id == "ego" else next(
        a for a in truth["actors"] if a["id"] == actor_id)["trajectory"]
    return {k: np.array([p[k] for p in points]) for k in points[0]}


def _iou(a, b) -> float:
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def _xyxy(b: dict) -> tuple[float, float, float, float]:
    return b["x1"], b["y1"], b["x2"], b["y2"]


# --------------------------------------------------------------------------- route and drive


def test_route_is_the_real_street(route):
    assert route.name == "Kaisaniemenranta"
    assert 300.0 <= route.length_m <= 500.0
    assert len(route.way_ids) == len(set(route.way_ids))
    heading = np.degrees(np.arctan2(*np.gradient(route.road.xy_m, axis=0)[:, ::-1].T))
    assert heading.max() - heading.min() > 20.0  # the gentle left bend


def test_files_and_manifest(sample):
    for p in (sample.video, sample.gps, sample.camera, sample.keyframes, sample.detections,
              sample.truth, sample.manifest):
        assert p.exists() and p.stat().st_size > 0, p
    manifest = json.loads(sample.manifest.read_text())
    assert {v["path"] for v in manifest["files"].values()} == {
        p.name for p in (sample.video, sample.gps, sample.camera, sample.keyframes,
                         sample.detections, sample.truth)}
    assert sample.n_frames == 240 and sample.fps == 10.0
    assert not list(sample.out_dir.glob(".*"))  # no temporary files left behind


def test_video_is_readable_with_all_frames(sample):
    import cv2

    cap = cv2.VideoCapture(str(sample.video))
    try:
        assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == sample.n_frames
        assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(sample.fps)
        ok, img = cap.read()
        assert ok and img.shape == (sample.height, sample.width, 3)
    finally:
        cap.release()


def test_camera_file_round_trips(sample):
    cam = load_camera(sample.camera)
    assert cam == demo_camera(sample.width, sample.height)
    assert cam.pitch_deg == pytest.approx(1.5)
    assert "pitch_deg: 1.500" in sample.camera.read_text()


def test_lead_brakes_and_cut_in_merges(truth):
    t = _traj(truth, "lead")["t"]
    v_lead = _traj(truth, "lead")["speed"]
    assert v_lead[0] == pytest.approx(13.0, abs=0.05)
    assert v_lead[-1] == pytest.approx(6.0, abs=0.05)
    decel = -np.gradient(v_lead, t)
    assert 2.6 < decel.max() < 3.3
    ego = _traj(truth, "ego")
    assert 12.0 <= ego["speed"][:50].mean() <= 15.0
    assert ego["speed"].min() > 5.0
    # Lateral offset of the cut-in in the ego frame: from the left lane to the ego lane,
    # ahead of the ego and behind the lead at the end.
    cut = _traj(truth, "cutin")
    lead = _traj(truth, "lead")

    def ego_frame(a):
        dx, dy = a["x"] - ego["x"], a["y"] - ego["y"]
        c, s = np.cos(ego["heading"]), np.sin(ego["heading"])
        return c * dx + s * dy, -s * dx + c * dy

    cut_fwd, cut_lat = ego_frame(cut)
    lead_fwd, lead_lat = ego_frame(lead)
    assert cut_lat[0] == pytest.approx(3.5, abs=0.3)
    assert abs(cut_lat[-1]) < 0.5 and abs(lead_lat[-1]) < 0.8  # the road still curves a little
    assert cut_fwd[0] < 0.0 < cut_fwd[-1] < lead_fwd[-1]
    # Nobody collides with the ego: bumper gaps stay positive in its lane.
    in_lane = np.abs(cut_lat) < 1.8
    assert (cut_fwd[in_lane] - 4.6 / 2 - 1.9 > 2.0).all()


def test_truth_converts_to_a_valid_scenario(sample, tmp_path):
    from vid2sim.core import scenario as sc

    scen = truth_scenario(sample.truth)
    sc.save(scen, tmp_path / "truth_scenario.json")
    back = sc.load(tmp_path / "truth_scenario.json")
    assert {a.id for a in back.actors} == {"lead", "cutin", "oncoming1", "oncoming2", "parked1",
                                           "parked2", "parked3"}
    parked = next(a for a in back.actors if a.id == "parked1")
    assert parked.trajectory.speed.max() < 1e-3  # stationary stays at 0
    assert back.roads[0].osm_way_ids == json.loads(sample.truth.read_text())["road"]["osm_way_ids"]
    assert back.duration_s == pytest.approx(23.9)


def test_truth_positions_agree_with_lat_lon(truth):
    frame = EnuFrame(Origin(**truth["origin"]))
    ego = _traj(truth, "ego")
    enu = frame.to_enu(ego["lat"], ego["lon"])
    assert np.abs(enu[:, 0] - ego["x"]).max() < 0.01
    assert np.abs(enu[:, 1] - ego["y"]).max() < 0.01


# --------------------------------------------------------------------------- GPS


def test_gps_noise_statistics():
    err = gps_noise_enu(20000, np.random.default_rng(0), sigma_m=3.0, rho=0.5)
    assert err.std(axis=0) == pytest.approx([3.0, 3.0], rel=0.05)
    assert np.abs(err.mean(axis=0)).max() < 0.15
    for k in (0, 1):
        lag1 = np.corrcoef(err[:-1, k], err[1:, k])[0, 1]
        assert lag1 == pytest.approx(0.5, abs=0.05)


def test_gpx_is_readable_and_aligned_with_the_video(sample, truth):
    import gpxpy

    gpx = gpxpy.parse(sample.gps.read_text())
    points = [p for tr in gpx.tracks for seg in tr.segments for p in seg.points]
    assert len(points) == 25
    assert points[0].time == VIDEO_START_UTC
    assert all(b.time - a.time == timedelta(seconds=1) for a, b in itertools.pairwise(points))
    speeds = [float(p.extensions[0].find(f"{{{GARMIN_TPX_NS}}}speed").text) for p in points]
    ego = _traj(truth, "ego")
    true_speed = np.interp(np.arange(25.0), ego["t"], ego["speed"])
    assert np.abs(np.array(speeds) - true_speed)[:-1].max() < 0.8
    # Position errors: about 3 m per axis (25 correlated fixes: loose bounds).
    frame = EnuFrame(Origin(**truth["origin"]))
    enu = frame.to_enu([p.latitude for p in points], [p.longitude for p in points])
    x_true = np.interp(np.arange(25.0), ego["t"], ego["x"])
    y_true = np.interp(np.arange(25.0), ego["t"], ego["y"])
    err = np.column_stack((enu[:, 0] - x_true, enu[:, 1] - y_true))[:-1]
    rms = np.sqrt((err ** 2).mean())
    assert 1.0 < rms < 6.0
    recorded = np.array([[f["err_east_m"], f["err_north_m"]] for f in truth["gps_fixes"]])[:-1]
    assert np.abs(err - recorded).max() < 0.05


def test_project_gps_reader_reads_the_gpx(sample):
    readers = pytest.importorskip("vid2sim.geo.readers")
    trace = readers.read_gps(sample.gps)
    assert len(trace.fixes) == 25
    assert trace.fixes[0].t_utc_s == pytest.approx(VIDEO_START_UTC.timestamp())


# --------------------------------------------------------------------------- annotations


def test_keyframes_are_the_visible_truth(sample, truth):
    keyframes = json.loads(sample.keyframes.read_text())
    assert [k["index"] for k in keyframes] == [round((KEYFRAME_OFFSET_S + j) * 10)
                                              for j in range(24)]
    n_labels = 0
    for kf in keyframes:
        assert kf["timestamp"] == kf["index"] * 100
        frame = truth["frames"][kf["index"]]
        visible = {b["id"]: b for b in frame["boxes"] if b["visible"]}
        # The rule: wholly in front of the camera, at least half in the image, at most 80%
        # hidden (what a replay can project and a detector can see).
        assert all(b["in_front"] and b["in_image_fraction"] >= 0.5
                   and b["visible_fraction"] >= 0.2 for b in visible.values())
        assert {lab["id"] for lab in kf["labels"]} == set(visible)
        for lab in kf["labels"]:
            box = _xyxy(lab["box2d"])
            assert box == _xyxy(visible[lab["id"]]["box2d"])
            assert 0 <= box[0] < box[2] <= sample.width - 1
            assert 0 <= box[1] < box[3] <= sample.height - 1
            assert box[2] - box[0] >= 10 and box[3] - box[1] >= 10
            assert lab["category"] == "car"
            n_labels += 1
    assert n_labels >= 40  # lead and cut-in most of the time, oncoming traffic at times


def test_truth_boxes_lie_inside_the_projected_3d_boxes_of_truth_poses(sample, truth):
    """Recompute each vehicle's 3D box from truth.json's poses with Camera.project_box
    (independent of the renderer) wherever it is whole in front of the camera: the truth box
    (the drawn outline) lies inside it and fills most of its width."""
    cam = load_camera(sample.camera)
    ego = _traj(truth, "ego")
    actors = {a["id"]: a for a in truth["actors"]}
    checked = 0
    for fr in truth["frames"][::7]:
        i = fr["index"]
        c, s = math.cos(ego["heading"][i]), math.sin(ego["heading"][i])
        for b in fr["boxes"]:
            a = actors[b["id"]]
            p = a["trajectory"][i]
            dx, dy = p["x"] - ego["x"][i], p["y"] - ego["y"][i]
            center = np.array([c * dx + s * dy, -s * dx + c * dy])
            yaw = p["heading"] - ego["heading"][i]
            expected = cam.project_box(center, a["length_m"], a["width_m"], a["height_m"], yaw)
            if expected is None or b["box2d"] is None or center[0] > 150:
                continue
            got = np.array(_xyxy(b["box2d"]))
            lo, hi = np.array(expected[:2]), np.array(expected[2:])
            assert (got[:2] >= lo - 0.05).all() and (got[2:] <= hi + 0.05).all(), (i, b["id"])
            assert got[2] - got[0] >= 0.8 * (hi[0] - lo[0]), (i, b["id"])
            checked += 1
    assert checked > 20


def test_project_annotation_reader_reads_keyframes(sample):
    annotations = pytest.importorskip("vid2sim.evaluate.annotations")
    kfs = annotations.read_keyframes(sample.keyframes, fps=sample.fps)
    assert len(kfs) == 24
    assert kfs[0].t_s == pytest.approx(KEYFRAME_OFFSET_S)


# --------------------------------------------------------------------------- detections


def test_detections_are_noisy_truth(sample, truth):
    rows = [line.split(",") for line in sample.detections.read_text().splitlines()]
    assert all(len(r) == 10 and r[1] == "-1" and r[7:] == ["-1", "-1", "-1"] for r in rows)
    by_frame: dict[int, list] = {}
    for r in rows:
        x, y, w, h, score = map(float, r[2:7])
        assert 0.5 <= score <= 0.95 and w > 0 and h > 0
        by_frame.setdefault(int(r[0]), []).append((x, y, x + w, y + h))
    assert min(by_frame) >= 1 and max(by_frame) <= sample.n_frames
    n_true = n_found = 0
    ious = []
    for fr in truth["frames"]:
        dets = list(by_frame.get(fr["index"] + 1, []))
        for b in fr["boxes"]:
            if not b["visible"]:
                continue
            n_true += 1
            best = max(((_iou(_xyxy(b["box2d"]), d), d) for d in dets), default=(0.0, None))
            if best[0] >= 0.5:
                n_found += 1
                ious.append(best[0])
                dets.remove(best[1])
    recall = n_found / n_true
    assert 0.9 <= recall <= 0.995
    assert 0.8 <= float(np.mean(ious)) <= 0.97  # jittered, not copied
    n_fp = len(rows) - n_found
    assert n_fp <= 0.05 * len(rows)


# --------------------------------------------------------------------------- determinism


def _small(route, out: Path, seed: int) -> DemoSample:
    return generate_demo_sample(out, seed=seed, duration_s=3.0, fps=5.0, width=480,
                                height=270, route=route)


def test_same_seed_same_bytes(route, tmp_path):
    a = _small(route, tmp_path / "a", 3)
    b = _small(route, tmp_path / "b", 3)
    for name in ("gps", "camera", "keyframes", "detections", "truth", "manifest"):
        assert getattr(a, name).read_bytes() == getattr(b, name).read_bytes(), name
    c = _small(route, tmp_path / "c", 4)
    assert c.gps.read_bytes() != a.gps.read_bytes()
    ta, tc = json.loads(a.truth.read_text()), json.loads(c.truth.read_text())
    assert ta["ego"] == tc["ego"] and ta["actors"] == tc["actors"]  # the drive is seed-free


def test_ego_drives_the_right_hand_lane(truth, route):
    ego = _traj(truth, "ego")
    xy = np.column_stack((ego["x"], ego["y"]))
    line = route.road.xy_m
    d2 = ((xy[:, None, :] - line[None, ::2, :]) ** 2).sum(axis=2)
    dist = np.sqrt(d2.min(axis=1))
    assert np.allclose(dist, abs(EGO_LANE_OFFSET_M), atol=0.1)


def test_compare_to_truth_measures_errors(sample):
    """Truth against itself scores zero; moved to another origin and shifted 2 m north it
    scores the shift (the origin change is undone through WGS-84)."""
    from dataclasses import replace

    truth = truth_scenario(sample.truth)
    same = compare_to_truth(truth, sample.truth)
    assert same["ego"]["along_m"] < 1e-3 and same["ego"]["cross_m"] < 1e-3
    assert all(a["id"] == a["truth_id"] and a["mean_m"] < 1e-3 for a in same["actors"])

    old = EnuFrame(truth.origin)
    new_origin = Origin(truth.origin.lat + 0.001, truth.origin.lon - 0.002, 0.0)
    new = EnuFrame(new_origin)

    def moved(tr):
        lat, lon, _ = old.to_geodetic(np.column_stack((tr.x, tr.y + 2.0)))
        p = new.to_enu(lat, lon)
        return replace(tr, x=p[:, 0], y=p[:, 1])

    shifted = replace(truth, origin=new_origin,
                      ego=replace(truth.ego, trajectory=moved(truth.ego.trajectory)),
                      actors=[replace(a, trajectory=moved(a.trajectory)) for a in truth.actors])
    res = compare_to_truth(shifted, sample.truth)
    ego_err = np.hypot(res["ego"]["along_m"], res["ego"]["cross_m"])
    assert ego_err == pytest.approx(2.0, abs=0.01)
    assert all(a["mean_m"] == pytest.approx(2.0, abs=0.01) for a in res["actors"])
