"""IoU, Hungarian matching and the two counting rules, on cases with known answers."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.core.records import AnnotatedBox, Keyframe, ProjectedBox
from vid2sim.evaluate.metrics import iou_matrix, match_boxes, score_frame, score_keyframes


def pb(box, aid="a", range_m=10.0, hard=False):
    return ProjectedBox(actor_id=aid, box_px=tuple(map(float, box)), category="car",
                        range_m=range_m, hard=hard)


def ab(box, ignore=False, range_m=None, aid=None):
    return AnnotatedBox(box_px=tuple(map(float, box)), category="car", id=aid,
                        range_m=range_m, ignore=ignore)


def shifted(box, dx):
    return (box[0] + dx, box[1], box[2] + dx, box[3])


# --------------------------------------------------------------------------- IoU


def test_iou_known_values():
    a = [[0, 0, 10, 10]]
    assert iou_matrix(a, [[0, 0, 10, 10]])[0, 0] == pytest.approx(1.0)
    assert iou_matrix(a, [[5, 0, 15, 10]])[0, 0] == pytest.approx(50 / 150)
    assert iou_matrix(a, [[0, 0, 5, 5]])[0, 0] == pytest.approx(25 / 100)
    assert iou_matrix(a, [[10, 10, 20, 20]])[0, 0] == 0.0  # touching corners
    assert iou_matrix(a, [[0, 0, 0, 0]])[0, 0] == 0.0  # degenerate box, no NaN
    assert iou_matrix(np.zeros((0, 4)), a).shape == (0, 1)


boxes = st.tuples(st.floats(0, 500), st.floats(0, 300), st.floats(1, 200),
                  st.floats(1, 200)).map(lambda b: (b[0], b[1], b[0] + b[2], b[1] + b[3]))


@given(st.lists(boxes, min_size=1, max_size=6), st.lists(boxes, min_size=1, max_size=6))
@settings(max_examples=60, deadline=None)
def test_iou_is_symmetric_bounded_and_one_on_itself(a, b):
    m = iou_matrix(a, b)
    assert np.allclose(m, iou_matrix(b, a).T)
    assert (m >= 0).all() and (m <= 1 + 1e-12).all()
    assert np.allclose(np.diag(iou_matrix(a, a)), 1.0)


# --------------------------------------------------------------------------- matching


def test_match_prefers_more_pairs_over_larger_iou_sum():
    # Pred 0 overlaps gt 0 (IoU 0.95) and gt 1 (IoU ~0.6); pred 1 overlaps only gt 0 (~0.6).
    # Maximising the IoU sum alone might pair (0, 0) and leave pred 1 alone; the count must win.
    gt = [(0, 0, 100, 100), (20, 0, 120, 100)]
    pred = [(2, 0, 102, 100), (-25, 0, 75, 100)]
    iou = iou_matrix(pred, gt)
    pairs = match_boxes(pred, gt)
    assert len(pairs) == 2
    assert {(i, j) for i, j, _ in pairs} == {(0, 1), (1, 0)}
    assert all(v >= 0.5 for _, _, v in pairs)
    assert iou[0, 0] > iou[0, 1]  # the greedy choice would have been (0, 0)


def test_match_is_one_to_one_and_thresholded():
    gt = [(0, 0, 10, 10)]
    pred = [(0, 0, 10, 10), (1, 0, 11, 10)]
    pairs = match_boxes(pred, gt)
    assert pairs == [(0, 0, 1.0)]
    assert match_boxes([(6, 0, 16, 10)], gt) == []  # IoU 0.25 < 0.5
    assert match_boxes([(6, 0, 16, 10)], gt, min_iou=0.1)[0][2] == pytest.approx(0.25)
    # strict: IoU exactly at the threshold is not admitted
    assert match_boxes([(0, 0, 10, 10)], [(0, 0, 10, 10)], min_iou=1.0, strict=True) == []
    assert match_boxes([], gt) == [] and match_boxes(pred, []) == []


@given(st.lists(boxes, max_size=6), st.lists(boxes, max_size=6))
@settings(max_examples=60, deadline=None)
def test_hungarian_finds_the_largest_number_of_pairs(pred, gt):
    pairs = match_boxes(pred, gt)
    assert len({i for i, _, _ in pairs}) == len(pairs) == len({j for _, j, _ in pairs})
    iou = iou_matrix(pred, gt)
    # brute force: every injective assignment of the smaller side into the larger one
    best = 0
    if pred and gt:
        m = iou if len(pred) <= len(gt) else iou.T
        for perm in itertools.permutations(range(m.shape[1]), m.shape[0]):
            best = max(best, sum(m[i, perm[i]] >= 0.5 for i in range(m.shape[0])))
    assert len(pairs) == best


# --------------------------------------------------------------------------- counting rules


def test_counting_rules_per_frame():
    g = [(0, 0, 100, 100), (200, 0, 300, 100), (400, 0, 500, 100), (600, 0, 700, 100)]
    pred = [
        pb((0, 0, 100, 100), "tp"),  # IoU 1 -> TP both rules
        pb(shifted(g[1], 50), "weak"),  # IoU 1/3 -> FP+FN standard, FP reference
        pb(shifted(g[2], 90), "poor"),  # IoU 10/190 ~ 0.05 -> FP+FN standard, FN reference
        pb((900, 0, 950, 50), "stray"),  # no overlap -> FP standard, uncounted reference
    ]  # g[3] has no prediction -> FN both rules
    s = score_frame(pred, [ab(b) for b in g])
    assert (s.tp, s.fp, s.fn) == (1, 3, 3)
    assert (s.ref_tp, s.ref_fp, s.ref_fn) == (1, 1, 2)
    assert s.ious == [1.0]
    assert s.ref_ious == pytest.approx([1.0, 1 / 3])


def test_ignore_regions_neither_reward_nor_penalise():
    gt = [ab((0, 0, 100, 100)), ab((300, 0, 400, 100), ignore=True)]
    pred = [pb((0, 0, 100, 100)), pb((310, 10, 390, 90), "in_dontcare"),
            pb((370, 0, 470, 100), "30pct_inside")]
    s = score_frame(pred, gt)
    assert (s.tp, s.fp, s.fn, s.ignored) == (1, 1, 0, 1)
    # an ignore region is never a FN
    s2 = score_frame([], gt)
    assert (s2.tp, s2.fp, s2.fn) == (0, 0, 1)


def test_empty_denominators_give_numbers():
    # annotations but no simulated boxes, and the reverse
    none_simulated = score_keyframes([Keyframe(0, 0.0, "a", [ab((0, 0, 9, 9))])], [[]])
    assert (none_simulated["precision"], none_simulated["recall"], none_simulated["f1"]) == (0, 0, 0)
    invented = score_keyframes([Keyframe(0, 0.0, "a", [])], [[pb((0, 0, 9, 9))]])
    assert (invented["precision"], invented["recall"], invented["f1"]) == (0, 0, 0)
    assert invented["mean_iou"] == 0.0


def test_hard_simulated_boxes_count_only_when_matched():
    gt = [ab((0, 0, 100, 100))]
    pred = [pb((0, 0, 100, 100), "matched_hard", hard=True), pb((300, 0, 305, 6), "tiny",
                                                                 hard=True)]
    s = score_frame(pred, gt)
    assert (s.tp, s.fp, s.fn, s.ignored) == (1, 0, 0, 1)
    s = score_frame([pb((300, 0, 305, 6), "tiny", hard=False)], gt)
    assert (s.tp, s.fp, s.fn) == (0, 1, 1)


def test_score_keyframes_contract_and_totals():
    kfs = [Keyframe(0, 0.0, "a", [ab((0, 0, 100, 100), range_m=20.0), ab((200, 0, 300, 100))]),
           Keyframe(5, 0.5, "b", [ab((0, 0, 50, 50))]),
           Keyframe(9, 0.9, "empty", [])]
    preds = {0.0: [pb((0, 0, 100, 100), range_m=21.5), pb((500, 0, 600, 100), "x")],
             0.5: [pb((0, 0, 50, 50), range_m=7.0)], 0.9: []}
    m = score_keyframes(kfs, preds)
    for key in ("keyframes", "tp", "fp", "fn", "precision", "recall", "f1", "mean_iou",
                "per_keyframe"):
        assert key in m
    assert (m["keyframes"], m["tp"], m["fp"], m["fn"]) == (3, 2, 1, 1)
    assert m["precision"] == pytest.approx(2 / 3)
    assert m["recall"] == pytest.approx(2 / 3)
    assert m["f1"] == pytest.approx(2 / 3)
    assert m["mean_iou"] == pytest.approx(1.0)
    assert m["range_error"]["pairs"] == 1
    assert m["range_error"]["mean_signed_m"] == pytest.approx(1.5)
    last = m["per_keyframe"][2]
    # nothing annotated, nothing simulated: perfect, and still numbers
    assert (last["precision"], last["recall"], last["f1"], last["mean_iou"]) == (1, 1, 1, 0)
    assert m["per_keyframe"][0]["matches"][0]["range_error_m"] == pytest.approx(1.5)
    assert m["per_keyframe"][0]["false_positive_actors"] == ["x"]
    assert m["per_keyframe"][0]["missed_annotations"] == [None]  # the box without an id
    # a list parallel to the keyframes gives the same result
    assert score_keyframes(kfs, [preds[0.0], preds[0.5], []])["f1"] == m["f1"]
    with pytest.raises(ValueError):
        score_keyframes(kfs, [[]])
