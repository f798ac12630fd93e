"""Detector maths on hand-built tensors, plus the accuracy bar on real KITTI frames."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from vid2sim.base.errors import FormatError
from vid2sim.core.boxes import cut_by_window, iou_matrix, nms, suppress_fragments
from vid2sim.detect.vehicles.detector import (
    COCO_VEHICLES,
    DEFAULT_DETECTOR,
    REFINE_MAX_BOXES,
    PicodetDetector,
    YoloxDetector,
    decode_picodet,
    decode_yolox,
    letterbox,
    load_detector,
)
from vid2sim.detect.vehicles.external import (
    MatchCounts,
    read_kitti_tracking_labels,
    score_against_kitti,
)
from vid2sim.detect.vehicles.windows import (
    REFINE_CROP_SCALE,
    REFINE_MIN_SIDE_PX,
    refine_candidates,
    refine_crop,
    tile_windows,
)

CAR, TRUCK, PERSON = 2, 7, 0


def test_letterbox_scale_and_padding():
    image = np.zeros((375, 1242, 3), np.uint8)
    canvas, r = letterbox(image)
    assert canvas.shape == (416, 416, 3)
    assert r == pytest.approx(416 / 1242)
    # 375 * r = 125.6 -> 125 rows of image (floor, as upstream), the rest is fill
    assert (canvas[:125] == 0).all()
    assert (canvas[126:] == 114).all()


def test_decode_yolox_known_cell():
    out = np.zeros((1, 3549, 85), np.float32)
    row = 3 * 52 + 5  # stride 8, grid x 5, y 3
    out[0, row, :5] = [0.5, 0.25, math.log(4.0), math.log(2.0), 0.9]
    out[0, row, 5 + CAR] = 0.8
    row16 = 52 * 52 + 2 * 26 + 1  # stride 16, grid x 1, y 2
    out[0, row16, :5] = [0.0, 0.0, 0.0, 0.0, 0.5]
    out[0, row16, 5 + TRUCK] = 0.6
    boxes, scores = decode_yolox(out)
    assert boxes[row] == pytest.approx([28.0, 18.0, 60.0, 34.0])
    assert scores[row, CAR] == pytest.approx(0.72)
    # stride 16: centre (1 * 16, 2 * 16), size exp(0) * 16
    assert boxes[row16] == pytest.approx([8.0, 24.0, 24.0, 40.0])
    assert scores[row16, TRUCK] == pytest.approx(0.3)


def _picodet_outputs(cells):
    """Picodet-shaped outputs with given cells: (stride, row, col, class, score, ltrb bins)."""
    cls, reg = [], []
    for s in (8, 16, 32, 64):
        n = math.ceil(416 / s) ** 2
        cls.append(np.zeros((1, n, 80), np.float32))
        reg.append(np.zeros((1, n, 32), np.float32))
    for stride, row, col, c, score, ltrb in cells:
        level = (8, 16, 32, 64).index(stride)
        g = math.ceil(416 / stride)
        idx = row * g + col
        cls[level][0, idx, c] = score
        logits = np.full((4, 8), -50.0, np.float32)
        for side, k in enumerate(ltrb):
            logits[side, k] = 50.0  # one-hot distribution: expectation = k bins
        reg[level][0, idx] = logits.ravel()
    return cls, reg


def test_decode_picodet_known_cell():
    cls, reg = _picodet_outputs([(16, 2, 4, CAR, 0.7, (2, 1, 3, 4))])
    boxes, scores = decode_picodet(cls, reg)
    best = scores[:, CAR].argmax()
    assert scores[best, CAR] == pytest.approx(0.7)
    # centre ((4 + 0.5) * 16, (2 + 0.5) * 16) = (72, 40); sides 2, 1, 3, 4 bins of 16 px
    assert boxes[best] == pytest.approx([40.0, 24.0, 120.0, 104.0], abs=1e-3)


def test_decode_picodet_soft_distribution_uses_expectation():
    cls, reg = _picodet_outputs([(8, 0, 0, CAR, 0.9, (0, 0, 0, 0))])
    logits = np.full((4, 8), -50.0, np.float32)
    logits[:, 1] = 0.0
    logits[:, 2] = 0.0  # equal mass on bins 1 and 2 -> expectation 1.5
    reg[0][0, 0] = logits.ravel()
    boxes, scores = decode_picodet(cls, reg)
    best = scores[:, CAR].argmax()
    assert boxes[best] == pytest.approx([4 - 12, 4 - 12, 4 + 12, 4 + 12], abs=1e-3)


def test_nms_class_aware_and_agnostic():
    boxes = np.array([[0, 0, 10, 10], [1, 0, 11, 10], [50, 50, 60, 60]], float)
    scores = np.array([0.6, 0.9, 0.5])
    assert nms(boxes, scores, 0.45).tolist() == [1, 2]
    # different classes are not suppressed by class-aware NMS
    assert sorted(nms(boxes, scores, 0.45, np.array([CAR, TRUCK, CAR])).tolist()) == [0, 1, 2]
    assert nms(np.zeros((0, 4)), np.zeros(0), 0.5).size == 0


def test_tile_windows_cover_wide_frames_only():
    wins = tile_windows(1242, 375)
    assert wins[0] == (0, 0, 1242, 375)
    (l0, _, l1, _), (r0, _, r1, _) = wins[1], wins[2]
    assert l0 == 0 and r1 == 1242
    assert l1 - l0 == r1 - r0 == round(621 * 1.1)
    assert l1 > r0  # the tiles overlap in the middle
    # The centre window: a square of a third of the width (at most the height) about the
    # image centre, where a forward camera sees the road ahead.
    assert wins[3] == (433, 0, 808, 375)
    assert tile_windows(1280, 720)[3] == (426, 146, 853, 573)
    assert len(tile_windows(1242, 375, centre=False)) == 3
    assert tile_windows(640, 480) == [(0, 0, 640, 480)]


def test_fragment_of_a_car_is_suppressed_but_a_far_car_is_kept():
    boxes = np.array([[100, 100, 300, 200],   # near car
                      [200, 110, 300, 195],   # its rear half (a fragment): similar height
                      [180, 130, 210, 150]],  # far car seen over it: small
                     float)
    scores = np.array([0.9, 0.5, 0.4])
    assert suppress_fragments(boxes, scores).tolist() == [0, 2]


class _FakeSession:
    """Stands in for onnxruntime in post-processing tests: returns fixed outputs."""

    def __init__(self, outputs):
        self.outputs = outputs
        self.inputs = []

    def run(self, _names, feeds):
        self.inputs.append(next(iter(feeds.values())))
        return self.outputs


def _fake(cls, outputs, **kw):
    det = cls.__new__(cls)
    det.session = _FakeSession(outputs)
    det.input_name = "x"
    det.input_size_px = (416, 416)
    det.score_threshold = kw.get("score_threshold", 0.3)
    det.nms_iou = kw.get("nms_iou", 0.45)
    det.small_object_mode = False
    det.refine_max_boxes = kw.get("refine_max_boxes", 0)
    det.refine_scale = kw.get("refine_scale", REFINE_CROP_SCALE)
    det.refine_min_side_px = kw.get("refine_min_side_px", REFINE_MIN_SIDE_PX)
    return det


def test_yolox_detector_maps_boxes_back_and_keeps_vehicles_only():
    out = np.zeros((1, 3549, 85), np.float32)
    car = 10 * 52 + 20
    out[0, car, :5] = [0.0, 0.0, math.log(4.0), math.log(2.0), 1.0]
    out[0, car, 5 + CAR] = 0.9
    person = 30 * 52 + 30
    out[0, person, :5] = [0.0, 0.0, 1.0, 1.0, 1.0]
    out[0, person, 5 + PERSON] = 0.99
    det = _fake(YoloxDetector, [out])
    image = np.zeros((375, 1242, 3), np.uint8)
    found = det.detect(image)
    assert len(found) == 1 and found[0].category == "car"
    r = 416 / 1242
    assert found[0].box_px == pytest.approx((144 / r, 72 / r, 176 / r, 88 / r), rel=1e-5)
    blob = det.session.inputs[0]
    assert blob.shape == (1, 3, 416, 416) and blob.dtype == np.float32
    assert blob[0, :, 300, 0] == pytest.approx([114, 114, 114])  # letterbox fill, 0-255


def test_picodet_detector_scales_plain_resize_and_normalises():
    cls, reg = _picodet_outputs([(16, 2, 4, TRUCK, 0.7, (2, 1, 3, 4))])
    det = _fake(PicodetDetector, cls + reg, nms_iou=0.6)
    image = np.full((832, 1248, 3), 255, np.uint8)
    (found,) = det.detect(image)
    assert found.category == "truck"
    assert found.box_px == pytest.approx((40 * 3, 24 * 2, 120 * 3, 104 * 2), abs=1e-2)
    blob = det.session.inputs[0]
    # white pixel, RGB order: (1 - mean) / std per channel
    assert blob[0, :, 0, 0] == pytest.approx([(1 - 0.485) / 0.229, (1 - 0.456) / 0.224,
                                              (1 - 0.406) / 0.225], rel=1e-5)


def test_vehicle_classes():
    # COCO's train (6) is the tram category (issue 19): trams are tracked as rail vehicles
    assert COCO_VEHICLES == {2: "car", 3: "motorcycle", 5: "bus", 6: "tram", 7: "truck"}


def test_load_detector_unknown_name(tmp_path):
    with pytest.raises(FormatError, match="yolo-v99"):
        load_detector("yolo-v99", tmp_path)


# --------------------------------------------------------------------------- real data


def _kitti_frames(tracking_dir: Path):
    for seq_dir in sorted((tracking_dir / "image_02").iterdir()):
        labels = read_kitti_tracking_labels(tracking_dir / "label_02" / f"{seq_dir.name}.txt")
        for png in sorted(seq_dir.glob("*.png")):
            yield cv2.imread(str(png)), labels.get(int(png.stem), [])


def test_default_model_reaches_the_kitti_bar(kitti_tracking_dir, model_dir):
    """Cars/vans (trunc < 0.5, occl <= 1, h >= 25 px): recall >= 0.85 at IoU 0.5 and
    precision >= 0.85 (rule in score_against_kitti), default detector and settings."""
    detector = load_detector(DEFAULT_DETECTOR, model_dir)
    total = MatchCounts(0, 0, 0, 0)
    for image, labels in _kitti_frames(kitti_tracking_dir):
        total = total + score_against_kitti(detector.detect(image), labels)
    assert total.n_targets == 25
    assert total.recall >= 0.85, total
    assert total.precision >= 0.85, total


@pytest.mark.parametrize("name", ["yolox-nano", "picodet-s"])
def test_both_decoders_find_the_near_car(kitti_tracking_dir, model_dir, name):
    image, labels = next(_kitti_frames(kitti_tracking_dir))  # 0001/000010
    near = next(lab for lab in labels if lab.track_id == 2)  # the unoccluded car ahead-right
    found = load_detector(name, model_dir, small_object_mode=False).detect(image)
    ious = iou_matrix(np.array([near.box_px]), np.array([d.box_px for d in found]))[0]
    best = int(ious.argmax())
    assert ious[best] >= 0.8
    assert found[best].category == "car" and found[best].score >= 0.5


def _yolox_output_with(boxes_canvas):
    """Raw YOLOX output encoding given canvas boxes (x1, y1, x2, y2, score) as stride-8 cars."""
    out = np.zeros((1, 3549, 85), np.float32)
    for x1, y1, x2, y2, score in boxes_canvas:
        cx, cy = (x1 + x2) / 2 / 8, (y1 + y2) / 2 / 8
        gx, gy = int(cx), int(cy)
        out[0, gy * 52 + gx, :5] = [cx - gx, cy - gy, math.log((x2 - x1) / 8),
                                    math.log((y2 - y1) / 8), 1.0]
        out[0, gy * 52 + gx, 5 + CAR] = score
    return out


class _PerCallSession(_FakeSession):
    def __init__(self, per_call):
        super().__init__(None)
        self.per_call = per_call

    def run(self, _names, feeds):
        self.inputs.append(next(iter(feeds.values())))
        return [self.per_call[len(self.inputs) - 1]]


def test_tiles_map_boxes_back_and_drop_boxes_cut_by_a_tile_edge():
    det = _fake(YoloxDetector, None)
    det.small_object_mode = True
    image = np.zeros((375, 1242, 3), np.uint8)
    (_, _, l_x2, _), (r_x1, _, _, _), (c_x1, _, c_x2, _) = tile_windows(1242, 375)[1:]
    r_tile = 416 / (l_x2 - 0)  # both tiles are wider than high: scale set by the width
    r_centre = 416 / (c_x2 - c_x1)
    det.session = _PerCallSession([
        _yolox_output_with([]),                                   # full frame: nothing
        _yolox_output_with([(380.0, 100.0, 416.0, 130.0, 0.8)]),  # left tile: cut at its edge
        _yolox_output_with([(100.0, 100.0, 140.0, 124.0, 0.7)]),  # right tile: whole car
        _yolox_output_with([(200.0, 150.0, 230.0, 170.0, 0.6),    # centre: a far car, and
                            (50.0, 150.0, 70.0, 165.0, 0.4)]),    # a weak box: dropped there
    ])
    found = det.detect(image)
    assert [d.score for d in found] == pytest.approx([0.7, 0.6])
    assert found[0].box_px == pytest.approx((r_x1 + 100 / r_tile, 100 / r_tile,
                                             r_x1 + 140 / r_tile, 124 / r_tile), rel=1e-4)
    assert found[1].box_px == pytest.approx((c_x1 + 200 / r_centre, 150 / r_centre,
                                             c_x1 + 230 / r_centre, 170 / r_centre), rel=1e-4)
    assert len(det.session.inputs) == 4


def test_tiles_recover_small_cars(kitti_tracking_dir, model_dir):
    """The small-car measure earns its cost: more small targets (25-40 px high) are found
    with the tiles than from the letterboxed full frame alone."""
    found = {}
    for tiles in (False, True):
        detector = load_detector(DEFAULT_DETECTOR, model_dir, small_object_mode=tiles)
        n = 0
        for image, labels in _kitti_frames(kitti_tracking_dir):
            small = [lab for lab in labels if lab.box_px[3] - lab.box_px[1] < 40]
            n += score_against_kitti(detector.detect(image), small).n_found
        found[tiles] = n
    assert found[True] >= found[False] + 3, found


def test_weights_under_another_name_get_the_right_decoder(model_dir, tmp_path):
    import shutil

    for filename, cls in (("yolox_nano.onnx", YoloxDetector),
                          ("picodet_s_416_coco.onnx", PicodetDetector)):
        renamed = tmp_path / f"my_{filename}"
        shutil.copyfile(model_dir / filename, renamed)
        det = load_detector(renamed, small_object_mode=False)
        assert type(det) is cls
        assert det.input_size_px == (416, 416)
    bad = tmp_path / "broken.onnx"
    bad.write_bytes(b"not a model")
    with pytest.raises(FormatError, match="broken.onnx"):  # not an ONNX model
        load_detector(bad, decoder="yolox")
    with pytest.raises(FormatError, match="broken.onnx"):
        load_detector(bad)


# --------------------------------------------------------------------------- crop refinement


def test_refine_crop_is_a_square_about_the_box_clipped_to_the_image():
    # 30 x 20 px box: side 4 * 30 = 120 about its centre (115, 200)
    assert refine_crop((100, 190, 130, 210), 1242, 375, 4.0, 96) == (55, 140, 175, 260)
    # a small box gets the minimum side, 96 px, not 4 * 10
    assert refine_crop((200, 195, 210, 205), 1242, 375, 4.0, 96) == (157, 152, 253, 248)
    # near the bottom-right corner the square is cut by the image
    assert refine_crop((1200, 330, 1240, 370), 1242, 375, 4.0, 96) == (1140, 270, 1242, 375)
    # the defaults
    side = max(REFINE_CROP_SCALE * 30, REFINE_MIN_SIDE_PX)
    assert refine_crop((100, 190, 130, 210), 1242, 375) == (
        round(115 - side / 2), round(200 - side / 2), round(115 + side / 2), round(200 + side / 2))
    assert refine_crop((100, 190, 130, 210), 1242, 375, scale=2.0, min_side_px=0) == \
        (85, 170, 145, 230)


def test_cut_by_window_ignores_edges_on_the_image_border():
    boxes = np.array([[0, 50, 40, 80],      # touches the crop's left edge = image border
                      [60, 50, 100, 99],    # touches the crop's bottom edge, inside the image
                      [60, 0.5, 100, 40],   # touches the crop's top edge (y1 = 0): kept
                      [20, 20, 60, 60]],    # inside
                     float)
    cut = cut_by_window(boxes, (0, 0, 120, 100), 1242, 375)
    assert cut.tolist() == [False, True, False, False]
    cut = cut_by_window(boxes, (0, 10, 120, 100), 1242, 375)
    assert cut.tolist() == [False, True, True, False]


def test_refine_candidates_are_mid_sized_boxes_ahead_nearest_first():
    # image centre line x = 621; a candidate's centre is at most 1.5 box widths from it
    boxes = np.array([[600, 180, 640, 210],   # 0: ahead, far
                      [580, 190, 660, 250],   # 1: ahead, nearest
                      [100, 180, 160, 260],   # 2: left edge of the image: not a lead
                      [610, 180, 616, 186],   # 3: tiny
                      [300, 100, 950, 370],   # 4: huge (over a quarter of the width)
                      [630, 185, 680, 225],   # 5: ahead, a bit to the right: 0.7 widths
                      [850, 200, 900, 270]],  # 6: parked at the kerb, near: 5 widths out
                     float)
    assert refine_candidates(boxes, 1242, 3).tolist() == [1, 5, 0]
    assert refine_candidates(boxes, 1242, 2).tolist() == [1, 5]
    assert refine_candidates(boxes, 1242, 5).tolist() == [1, 5, 0]
    assert refine_candidates(boxes, 1242, 3, max_offset_widths=6.0).tolist() == [6, 1, 5]
    assert refine_candidates(boxes, 1242, 0).size == 0
    assert refine_candidates(np.zeros((0, 4)), 1242, 3).size == 0


def test_refinement_replaces_the_matching_box_only():
    """A fake window pass finds, in the crop, a tighter box of the lead car, a box of a
    neighbouring car and a box cut by the crop edge: only the lead's box is replaced, by the
    crop box mapped back to frame pixels."""
    det = _fake(YoloxDetector, None, refine_max_boxes=2, refine_scale=4.0, refine_min_side_px=96)
    image = np.zeros((375, 1242, 3), np.uint8)
    lead = [600.0, 200.0, 640.0, 230.0]
    boxes = np.array([lead, [100.0, 200.0, 140.0, 230.0]])  # the second is not central
    crop = refine_crop(lead, 1242, 375, 4.0, 96)
    assert crop == (540, 135, 700, 295)  # 4 x 40 px about (620, 215)
    calls = []

    def fake_window(img):
        calls.append(img.shape)
        return (np.array([[62.0, 66.0, 98.0, 94.0],     # the lead, tighter: frame 602-638
                          [120.0, 70.0, 158.0, 100.0],  # a neighbour: no overlap
                          [0.5, 60.0, 30.0, 95.0]]),    # cut by the crop's left edge
                np.array([0.9, 0.8, 0.7]), np.array([CAR, CAR, CAR]))

    det._window = fake_window
    out = det.refine(image, boxes)
    assert calls == [(160, 160, 3)]  # one crop: the only central candidate
    assert out[0] == pytest.approx([602.0, 201.0, 638.0, 229.0])
    assert out[1] == pytest.approx(boxes[1])
    assert boxes[0] == pytest.approx(lead)  # the input is not modified


def test_refinement_keeps_the_box_without_a_good_match():
    det = _fake(YoloxDetector, None, refine_max_boxes=2, refine_scale=4.0, refine_min_side_px=96)
    image = np.zeros((375, 1242, 3), np.uint8)
    lead = np.array([[600.0, 200.0, 640.0, 230.0]])
    # only a box cut by the crop edge overlaps the lead well: it must not replace it
    det._window = lambda img: (np.array([[0.0, 60.0, 100.0, 95.0]]), np.array([0.9]),
                               np.array([CAR]))
    assert det.refine(image, lead) == pytest.approx(lead)
    # a whole box overlapping the lead with IoU 0.38 < 0.5
    det._window = lambda img: (np.array([[75.0, 65.0, 125.0, 95.0]]), np.array([0.9]),
                               np.array([CAR]))
    assert det.refine(image, lead) == pytest.approx(lead)


def test_detect_refines_after_merging_and_keeps_score_and_class():
    det = _fake(YoloxDetector, None, refine_max_boxes=1, refine_scale=4.0, refine_min_side_px=96)
    image = np.zeros((375, 1242, 3), np.uint8)
    seen = []

    def fake_window(img):
        seen.append(img.shape[:2])
        if len(seen) == 1:  # the full frame
            return np.array([[600.0, 200.0, 640.0, 232.0]]), np.array([0.6]), np.array([7])
        return np.array([[62.0, 66.0, 98.0, 94.0]]), np.array([0.95]), np.array([CAR])

    det._window = fake_window
    (found,) = det.detect(image)
    assert seen == [(375, 1242), (160, 160)]
    crop = refine_crop((600, 200, 640, 232), 1242, 375, 4.0, 96)
    assert found.box_px == pytest.approx((crop[0] + 62, crop[1] + 66, crop[0] + 98, crop[1] + 94))
    assert found.score == pytest.approx(0.6) and found.category == "truck"


def test_load_detector_refines_with_the_small_object_mode_only(model_dir):
    assert load_detector(DEFAULT_DETECTOR, model_dir).refine_max_boxes == REFINE_MAX_BOXES
    assert load_detector(DEFAULT_DETECTOR, model_dir, small_object_mode=False
                         ).refine_max_boxes == 0
    assert load_detector(DEFAULT_DETECTOR, model_dir, refine_max_boxes=0).refine_max_boxes == 0
