"""Composite clips: the pasted car lands where the camera projects its truth, the lead
trajectories keep their promises, and the real detector + tracker + ranging find the car.

Data-dependent tests skip when ../shared/data or the weights are absent (see conftest.py).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from vid2sim.core.camera import Camera, fit_camera_to_frames, load_camera
from vid2sim.samples import composite as cp

N_FRAMES = 108


def _pasted_box(cutout: cp.CarCutout, camera: Camera, range_m: float, lateral_m: float
                ) -> tuple[float, float, float, float]:
    """Box of the pixels the paste made at least half car (edges between pixels)."""
    gray = np.full((camera.image_height, camera.image_width, 3), 200, np.uint8)
    black = cp.CarCutout(**{**cutout.__dict__, "gray": np.zeros_like(cutout.gray)})
    out = cp.paste_car(gray, black, camera, range_m, lateral_m)
    ys, xs = np.nonzero(out[..., 0] < 100)
    return xs.min() - 0.5, ys.min() - 0.5, xs.max() + 0.5, ys.max() + 0.5


def _kitti_camera() -> Camera:
    return Camera(image_width=1242, image_height=375, fx=721.5377, fy=721.5377, cx=609.5593,
                  cy=172.854, height_m=1.65)


def test_synthetic_rear_face_lands_on_its_projection():
    """Known answer without data: a rectangle cut-out that is exactly a 1.8 x 1.5 m rear face
    seen at 10 m lands on the projection of that face at another range, lateral and pitch,
    all four edges within a pixel."""
    f, depth, w, h = 721.5377, 10.0, 1.8, 1.5
    wpx, hpx = f * w / depth, f * h / depth  # 129.9 x 108.2 px
    pad = 8
    gray = np.zeros((int(hpx) + 2 * pad, int(wpx) + 2 * pad), np.float32)
    left, top = pad - 0.5, pad - 0.5  # face edges in pixel-centre coordinates

    def coverage(n: int, lo: float, size: float) -> np.ndarray:
        c = np.arange(n, dtype=float)
        return np.clip(np.minimum(c + 0.5, lo + size) - np.maximum(c - 0.5, lo), 0.0, 1.0)

    # Anti-aliased face: each pixel's alpha is the share of it the face covers.
    alpha = np.outer(coverage(gray.shape[0], top, hpx), coverage(gray.shape[1], left, wpx))
    cut = cp.CarCutout(gray=gray, alpha=alpha.astype(np.float32),
                       anchor_px=(left + wpx / 2, top + hpx),
                       rear_box_px=(left, top, left + wpx, top + hpx),
                       depth_m=depth, focal_px=f, width_m=w, height_m=h, length_m=4.0,
                       source="synthetic")
    for r, y, pitch in ((8.0, 0.0, 0.0), (14.0, 0.35, 0.4), (25.0, -0.4, -0.3)):
        cam = _kitti_camera().with_pitch(pitch)
        face = cam.project(np.array([[r, y + w / 2, 0], [r, y - w / 2, 0], [r, y, h]]))[0]
        expect = (face[0, 0], face[2, 1], face[1, 0], face[0, 1])
        got = _pasted_box(cut, cam, r, y)
        # Blurred before shrinking, so a one-pixel edge can spread: within 1 px.
        np.testing.assert_allclose(got, expect, atol=1.0, err_msg=f"r={r} y={y} pitch={pitch}")


@pytest.fixture(scope="module")
def polo(kitti_tracking_dir):
    return cp.load_cutout(kitti_tracking_dir, "polo")


def test_polo_is_a_whole_rear_view_at_its_labelled_range(polo):
    # Label 0001/10 object 2: Z 8.14 m to the box centre, length 3.16 m -> rear at 6.57 m.
    assert polo.depth_m == pytest.approx(8.143 - 3.158 / 2, abs=0.05)
    # The pasted outline is the car's rear (tail lights to tail lights), narrower than the
    # label's 1.57 m 3D box: 1.49 m at its plane, the tyres' contact row (332), which lies
    # 0.19 m ahead of the label's rear face on the label's ground.
    assert 1.35 < polo.visible_width_m < polo.width_m
    assert 0.1 < polo.contact_m < 0.4
    assert polo.alpha.max() > 0.99 and polo.alpha[0].max() < 0.05  # feathered, not a slab


@pytest.mark.parametrize(("range_m", "lateral_m", "pitch_deg"),
                         [(8.0, 0.0, 0.0), (15.0, 0.3, 0.4), (30.0, -0.4, -0.5), (45.0, 0.1, 0.0)])
def test_pasted_car_lands_where_the_camera_projects_it(kitti_raw_dir, polo, range_m,
                                                       lateral_m, pitch_deg):
    """Left, right and bottom edges of the pasted car within 1.5 px of its truth box, the
    outline's (the hull of what the camera sees: the truth was a projected cuboid with the
    outline's width before issue 13), whose bottom is the road point ``contact_m`` ahead of
    the rear as the camera projects it. The top is lower than the box's top by up to 11 % of
    the height (the crop's top margin is feathered away)."""
    cam = load_camera(kitti_raw_dir / "camera.yaml").with_pitch(pitch_deg)
    truth = cp.truth_box(polo, cam, range_m, lateral_m)
    road = cam.project(np.array([[range_m + polo.contact_m, lateral_m, 0.0]]))[0][0]
    assert truth[3] == pytest.approx(road[1], abs=1.0)
    got = _pasted_box(polo, cam, range_m, lateral_m)
    for k in (0, 2, 3):
        assert got[k] == pytest.approx(truth[k], abs=1.5), (k, got, truth)
    height = truth[3] - truth[1]
    assert truth[1] - 1.0 <= got[1] <= truth[1] + 0.12 * height


def test_oxts_pitch_is_the_videos_vertical_motion(kitti_raw_dir):
    """The paste moves with the OXTS pitch; that is only right if the image does: the
    frame-to-frame vertical shift of the far background follows -f * d(pitch)."""
    import cv2

    cam = load_camera(kitti_raw_dir / "camera.yaml")
    cap = cv2.VideoCapture(str(kitti_raw_dir / "video.mp4"))
    window = np.outer(np.hanning(120), np.hanning(500))
    prev, shifts = None, []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        band = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)[110:230, 360:860].astype(np.float64)
        if prev is not None:
            shifts.append(cv2.phaseCorrelate(prev, band, window)[0][1])
        prev = band
    cap.release()
    expected = -cam.fy * np.tan(np.diff(cp.read_oxts_pitch(kitti_raw_dir)))
    assert len(shifts) == len(expected) == N_FRAMES - 1
    assert np.corrcoef(shifts, expected)[0, 1] > 0.9  # measured 0.98
    assert np.std(shifts) == pytest.approx(np.std(expected), rel=0.2)  # 0.70 vs 0.73 px


@pytest.mark.parametrize("seed", range(8))
def test_lead_profiles_keep_their_bounds(seed):
    tr = cp.lead_profile(seed, N_FRAMES)
    assert len(tr.t_s) == N_FRAMES and tr.t_s[1] == pytest.approx(0.1)
    assert tr.range_m.min() >= 8.0 and tr.range_m.max() <= 45.0
    assert np.abs(tr.range_rate_mps).max() <= 6.0
    assert tr.range_rate_mps.min() < -2.5 and tr.range_rate_mps.max() > 1.5  # close, open
    assert -4.0 - 1e-9 <= tr.rel_accel_mps2.min() <= -3.0  # a braking phase near -4 m/s^2
    assert np.abs(tr.lateral_m).max() <= 0.4 + 1e-9
    # The rate is the derivative of the range (central differences, 0.1 s apart).
    np.testing.assert_allclose(np.gradient(tr.range_m, tr.t_s)[1:-1], tr.range_rate_mps[1:-1],
                               atol=0.1)
    again = cp.lead_profile(seed, N_FRAMES)
    np.testing.assert_array_equal(again.range_m, tr.range_m)


# --------------------------------------------------------------------------- end to end

# The end-to-end clip: seed 1 starts at 19 m, closes to 9 m (braking at up to -3.6 m/s^2 to
# 3.4 m/s closing) and opens to 38 m at up to 5.8 m/s. The real detector takes ~20 s on its 108 frames.
E2E_SEED = 1


@pytest.fixture(scope="module")
def e2e(kitti_raw_dir, kitti_tracking_dir, model_dir, polo, tmp_path_factory):
    """Write one composite clip and run the real detector, tracker and ranging on it once."""
    from vid2sim.detect.pipeline import detect_and_range
    from vid2sim.detect.tracking.tracker import TrackerConfig
    from vid2sim.detect.vehicles.detector import load_detector
    from vid2sim.detect.video import video_info

    out = tmp_path_factory.mktemp("composite") / "clip.mp4"
    truth = cp.lead_profile(E2E_SEED, N_FRAMES)
    clip = cp.write_composite_clip(kitti_raw_dir, polo, truth, out)
    info = video_info(clip.video)
    camera, _ = fit_camera_to_frames(load_camera(kitti_raw_dir / "camera.yaml"), info.width,
                                     info.height)
    detector = load_detector("yolox-nano", model_dir, score_threshold=TrackerConfig().low_score)
    result, _, _ = detect_and_range(clip.video, camera, detector=detector, progress=False)
    return clip, info, result, cp.score_lead(result.boxes, truth, clip.boxes_px)


def test_clip_is_written_whole_with_its_truth(e2e, polo):
    clip, info, _, _ = e2e
    assert info.n_frames == N_FRAMES and (info.width, info.height) == (1242, 374)
    assert not list(clip.video.parent.glob(".*partial*"))
    doc = json.loads(clip.truth_json.read_text(encoding="utf-8"))
    assert len(doc["frames"]) == N_FRAMES and doc["body_pitch_from_oxts"] is True
    assert doc["frames"][40]["range_m"] == pytest.approx(float(clip.truth.range_m[40]), 1e-5)
    # Its box is the pasted outline's projection in that frame's pitched camera.
    expect = cp.truth_box(polo, clip.cameras[40], float(clip.truth.range_m[40]),
                          float(clip.truth.lateral_m[40]))
    np.testing.assert_allclose(doc["frames"][40]["box_px"], expect, atol=0.01)
    assert clip.cameras[40].pitch_deg != clip.cameras[41].pitch_deg  # the body pitch is in


def test_real_detector_ranges_the_composited_lead(e2e):
    """Regression bounds a little above the figures measured on this clip (seed 1, polo;
    ``pytest -s`` prints them). The bars for a recorded clip are 8 %, 0.5 m/s and 95 %. The
    range reads long by about its median error: the ranging learns a width of 1.63 m for a car
    whose rear outline is 1.45 m (see benchmarks/bench_composite.py)."""
    _, _, _, score = e2e
    print(f"\ncomposite seed {E2E_SEED}: {score}")
    # Measured with the detector's centre window (0.054 and 0.32 m/s without it at e83fd4b,
    # 0.041 and 0.46 at b5c7d87, 0.056 and 0.45 at f5df590).
    assert score.range_rel_err_median <= 0.07  # measured 0.054 (signed +0.054)
    assert score.range_rate_rmse_mps <= 0.55  # measured 0.42
    assert score.presence >= 0.95  # measured 1.00
    assert score.wrong_lead_frames == 0  # measured 0: nothing else taken for the lead
    assert len(score.car_track_ids) == 1  # measured one track: no id switch
