"""INT8 quantisation of the YOLOX-nano detector (issue 15): speed and accuracy, printed.

    python benchmarks/bench_int8.py [--shared ../shared] [--reps 25] [--variants NAME ...]
                                    [--no-speed] [--no-accuracy] [--keep DIR]

Builds quantised copies of the detector's dynamic-shape weights
(:func:`vid2sim.detect.vehicles._dynamic.dynamic_copy`) into a temporary folder with
``onnxruntime.quantization`` and compares them with the FP32 weights in one process:

1. Speed: milliseconds per onnxruntime call at the three input shapes a keyframe of KITTI
   (1242x374) runs with the default settings (full frame 1x3x160x416, the two tiles batched
   2x3x288x416, the centre window and refine crops 1x3x416x416; per keyframe 1 + 1 + 1.39
   calls of these on KITTI raw 0001), 2 intra-op threads, spinning off (as the detector sets
   its session), FP32 and every variant alternating call by call, best and median of
   ``--reps`` calls. FP32 also at the graph optimisation levels BASIC and EXTENDED (the
   detector uses onnxruntime's default, ALL).
2. Accuracy, the default detector (tiles, centre window, one refine crop, score >= 0.3) with
   its session swapped for the variant's: recall/precision on the six labelled KITTI tracking
   frames (``score_against_kitti``), and agreement with FP32's boxes (Hungarian on IoU >= 0.5)
   on held-out KITTI raw 0001 frames (54-107, every 2nd), the six KITTI tracking frames and
   the six TRI DGP front-camera frames: matched IoU, signed and absolute edge differences in
   frame pixels (variant minus FP32; the bottom edge is what ranging reads), unmatched boxes.

Variants (``VARIANTS``): ``dyn-u8`` is ``quantize_dynamic`` (QUInt8 weights, ConvInteger);
the static ones are ``quant_pre_process`` (onnxruntime's graph optimisation, onnx shape
inference; no symbolic shapes, sympy is not installed) of the FP32 copy converted to opset 13,
then ``quantize_static`` with per-channel QInt8 weights, in QDQ or QOperator format ("qop"),
QInt8 ("s8") or QUInt8 ("u8") activations, MinMax, Percentile (99.999) or Entropy
calibration, and node groups kept FP32: always the head's tail (sigmoids, concats, reshapes
and the transpose after the last convolutions: the one output tensor mixes box logits with
0-1 scores), optionally the last convolutions themselves, the first convolution (and its
SiLU: "stem"), or the 30 depthwise convolutions. "-conv" quantises only Conv nodes.

Calibration (static variants): windows of KITTI raw 0001 frames 0-51, every 3rd (18 frames),
prepared exactly as the detector prepares them (full frame, two tiles, centre window: 72
inputs; for Percentile/Entropy padded to the full 416x416 letterbox canvas, since onnxruntime's
histogram calibrators take one input shape); none of these frames is used for the accuracy
figures.
Figures depend on the machine and its load (2 shared cores): quote the ratios.

Measured 2026-12-02 (onnxruntime 1.32.0, onnx 1.23.2, 2 AVX-512 VNNI cores shared with other
sessions; ``python benchmarks/bench_int8.py``), per keyframe from the medians, x FP32:
FP32 ALL 1.00 (52.5 ms), EXTENDED 0.67, BASIC 0.59; dyn-u8 0.52; s8 activations 0.30-0.36
(onnxruntime fuses no QLinearConv for QInt8 activations on x86: the graph keeps 682
DequantizeLinear, 336 QuantizeLinear and float Convs); u8 activations, all ops 1.00-1.05
(QLinearConv 8.9 ms against FP32 Conv 13.9 ms at 416x416, but each SiLU becomes QLinearSigmoid
+ QLinearMul, 8.1 ms against FP32's fused QuickGelu 5.7 ms); u8, Conv only 0.72 (a
Quantize/Dequantize pair about every conv). Accuracy: every variant quantising the stem is
nearly blind (recall 0.00-0.40 against FP32's 0.92 on the six KITTI frames): the first conv
sees the unnormalised 0-255 input, its SiLU output spans 0-105 while the detail lies in a few
units, and quantising that one tensor alone cost the top-20 objectness 0.48 on average (a
scratch sensitivity run on KITTI raw 0001 frame 60). Keeping the first two convs and their
SiLUs FP32 ("stem2", MinMax) brings recall 0.88 / precision 0.75 (13 false of 52 against 7 of
48), matched boxes median |edge diff| 0.86-2.15 px, bottom-edge signed median +0.06 to +0.08
px, at 1.03x. No variant meets the bar of issue 15 (>= 1.3x per keyframe with recall and
precision within 0.02 of FP32): the detector stays FP32.
"""

from __future__ import annotations

import argparse
import copy
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import onnx
from onnx import version_converter
from onnxruntime.quantization import quant_pre_process

from vid2sim.core.boxes import iou_matrix, match
from vid2sim.core.records import Detection
from vid2sim.detect.vehicles._dynamic import dynamic_copy
from vid2sim.detect.vehicles.detector import ORT_SPINNING, load_detector
from vid2sim.detect.vehicles.external import (
    MatchCounts,
    read_kitti_tracking_labels,
    score_against_kitti,
)
from vid2sim.detect.vehicles.windows import tile_windows
from vid2sim.detect.video import iter_frames

SHAPES = ((1, 3, 160, 416), (2, 3, 288, 416), (1, 3, 416, 416))
"""Input shapes of one KITTI keyframe with the default settings (see the module docstring)."""

CALLS_PER_KEYFRAME = (1.0, 1.0, 1.39)
"""onnxruntime calls of each of SHAPES per keyframe on KITTI raw 0001 (108 frames: 108, 108 and
150 calls; the 416x416 calls are the centre window and the refine crops)."""

CALIB_FRAMES = range(0, 52, 3)
HELDOUT_FRAMES = range(54, 108, 2)
QDQ_OPSET = 13
"""Opset the FP32 weights are converted to before static quantisation (per-channel
DequantizeLinear takes an axis from opset 13 on)."""


@dataclass(frozen=True)
class Variant:
    """One way to build weights from the FP32 copy."""

    kind: str  # "fp32", "dynamic", "static"
    fmt: str = "qdq"  # "qdq" or "qop" (QOperator)
    activation: str = "s8"  # "s8" or "u8"
    method: str = "minmax"  # "minmax", "percentile", "entropy"
    ops: tuple[str, ...] | None = None  # op types to quantise (None: all the tool knows)
    # node groups kept FP32 (see head_nodes): "tail", "head_convs", "first_conv", "stem",
    # "stem2", "depthwise"
    exclude: tuple[str, ...] = ("tail",)
    opt_level: str = "all"  # session graph optimisation level
    extra: dict = field(default_factory=dict, hash=False, compare=False)


VARIANTS: dict[str, Variant] = {
    "fp32": Variant("fp32"),
    "fp32-extended": Variant("fp32", opt_level="extended"),
    "fp32-basic": Variant("fp32", opt_level="basic"),
    "dyn-u8": Variant("dynamic"),
    "qdq-s8": Variant("static"),
    "qdq-u8": Variant("static", activation="u8"),
    "qdq-s8-conv": Variant("static", ops=("Conv",)),
    "qop-u8": Variant("static", fmt="qop", activation="u8"),
    "qop-s8": Variant("static", fmt="qop"),
    "qdq-s8-headfp32": Variant("static", exclude=("tail", "head_convs", "first_conv")),
    "qdq-s8-pct": Variant("static", method="percentile"),
    "qdq-s8-entropy": Variant("static", method="entropy"),
    "qdq-u8-pct": Variant("static", activation="u8", method="percentile"),
    "qdq-u8-entropy": Variant("static", activation="u8", method="entropy"),
    "qdq-u8-pct-stem": Variant("static", activation="u8", method="percentile",
                               exclude=("tail", "stem")),
    "qdq-u8-conv": Variant("static", activation="u8", ops=("Conv",)),
    "qdq-u8-pct-nodw": Variant("static", activation="u8", method="percentile",
                               exclude=("tail", "depthwise")),
    "qdq-u8-stem2": Variant("static", activation="u8", exclude=("tail", "stem2")),
    "qdq-u8-pct-stem2": Variant("static", activation="u8", method="percentile",
                                exclude=("tail", "stem2")),
    "qdq-u8-pct-stemhead": Variant("static", activation="u8", method="percentile",
                                   exclude=("tail", "stem", "head_convs")),
}

DEFAULT_VARIANTS = ("fp32", "fp32-extended", "fp32-basic", "dyn-u8", "qdq-s8", "qop-s8", "qdq-u8",
                    "qop-u8", "qdq-u8-conv", "qdq-s8-headfp32", "qdq-u8-pct", "qdq-u8-entropy",
                    "qdq-u8-stem2", "qdq-u8-pct-stem2")
"""The variants of the figures in the report of issue 15 (the others were tried on the way)."""


# --------------------------------------------------------------------------- data


def kitti_tracking_frames(tracking: Path):
    """(name, image, labels) of the six labelled KITTI tracking frames."""
    out = []
    for seq_dir in sorted((tracking / "image_02").iterdir()):
        labels = read_kitti_tracking_labels(tracking / "label_02" / f"{seq_dir.name}.txt")
        for png in sorted(seq_dir.glob("*.png")):
            out.append((f"kitti-{seq_dir.name}-{png.stem}", cv2.imread(str(png)),
                        labels.get(int(png.stem), [])))
    return out


def raw_frames(video: Path, indices) -> list[tuple[str, np.ndarray]]:
    wanted = set(indices)
    return [(f"raw-{f.index}", f.image_bgr) for f in iter_frames(video, only=wanted)
            if f.index in wanted]


def dgp_frames(dgp: Path) -> list[tuple[str, np.ndarray]]:
    return [(f"dgp-{p.parent.parent.parent.name}-{p.stem}", cv2.imread(str(p)))
            for p in sorted(dgp.glob("scene_*/rgb/CAMERA_01/*.jpg"))]


def windows_of(detector, image: np.ndarray) -> list[np.ndarray]:
    """Network inputs (1, 3, H, W) of a frame's full frame, tiles and centre window."""
    h, w = image.shape[:2]
    return [detector._prepare(image[y1:y2, x1:x2])[0][None]
            for x1, y1, x2, y2 in tile_windows(w, h)]


class Reader:
    """onnxruntime calibration data reader over prepared windows."""

    def __init__(self, name: str, blobs: list[np.ndarray]):
        self.name, self.blobs, self.i = name, blobs, 0

    def get_next(self):
        if self.i >= len(self.blobs):
            return None
        self.i += 1
        return {self.name: self.blobs[self.i - 1]}

    def rewind(self):
        self.i = 0


def full_canvas(blob: np.ndarray, size_px: int = 416, fill: float = 114.0) -> np.ndarray:
    """A free-shape input (1, 3, H, W) padded right and below to the full letterbox canvas."""
    out = np.full((1, 3, size_px, size_px), fill, np.float32)
    out[:, :, :blob.shape[2], :blob.shape[3]] = blob
    return out


# --------------------------------------------------------------------------- building


def head_nodes(model) -> dict[str, list[str]]:
    """Node names of the detection head: the tail after the last convolutions (sigmoids,
    concats, reshapes, transpose producing the output), those convolutions, the first conv."""
    producer = {o: n for n in model.graph.node for o in n.output}
    tail, convs, stack, seen = [], [], [o.name for o in model.graph.output], set()
    while stack:
        node = producer.get(stack.pop())
        if node is None or node.name in seen:
            continue
        seen.add(node.name)
        if node.op_type == "Conv":
            convs.append(node.name)
            continue
        tail.append(node.name)
        stack.extend(node.input)
    first = next(n for n in model.graph.node if n.op_type == "Conv")
    # the first conv's SiLU: its Sigmoid and the Mul of the conv output by it
    silu = [n.name for n in model.graph.node
            if n.op_type in ("Sigmoid", "Mul") and first.output[0] in n.input]
    # the conv reading the stem's output and its SiLU too: the stem output then stays FP32
    # (the single activation whose quantisation hurt most, see the report)
    second = next(n for n in model.graph.node if n.op_type == "Conv"
                  and any(n.input[0] == m.output[0] for m in model.graph.node if m.name in silu))
    silu2 = [n.name for n in model.graph.node
             if n.op_type in ("Sigmoid", "Mul") and second.output[0] in n.input]
    depthwise = [n.name for n in model.graph.node if n.op_type == "Conv"
                 and any(a.name == "group" and a.i > 1 for a in n.attribute)]
    return {"tail": tail, "head_convs": convs, "first_conv": [first.name],
            "stem": [first.name, *silu], "stem2": [first.name, *silu, second.name, *silu2],
            "depthwise": depthwise}


def build(name: str, v: Variant, fp32: Path, pre: Path, out_dir: Path, reader: Reader) -> Path:
    """Weights of variant ``v`` (built into ``out_dir``; FP32 variants are the copy itself)."""
    from onnxruntime import quantization as q

    if v.kind == "fp32":
        return fp32
    target = out_dir / f"{name}.onnx"
    if v.kind == "dynamic":
        q.quantize_dynamic(pre, target, weight_type=q.QuantType.QUInt8)
        return target
    parts = head_nodes(onnx.load(str(pre)))
    exclude = [n for key in v.exclude for n in parts[key]]
    act = q.QuantType.QInt8 if v.activation == "s8" else q.QuantType.QUInt8
    method = {"minmax": q.CalibrationMethod.MinMax,
              "percentile": q.CalibrationMethod.Percentile,
              "entropy": q.CalibrationMethod.Entropy}[v.method]
    # flushes collected outputs every 10 runs (memory); not a divisor of the 72 inputs, since
    # onnxruntime 1.32 raises "No data is collected" when the last flush leaves none
    extra = {"CalibMaxIntermediateOutputs": 10, **v.extra}
    if v.method == "percentile":
        extra.setdefault("CalibPercentile", 99.999)
    reader.rewind()
    if v.method != "minmax":
        # onnxruntime's histogram calibrators stack the runs' outputs: one input shape only.
        # The free-shape inputs are crops of the full letterbox canvas: pad them back to it.
        reader = Reader(reader.name, [full_canvas(b) for b in reader.blobs])
    q.quantize_static(pre, target, reader,
                      quant_format=q.QuantFormat.QDQ if v.fmt == "qdq" else q.QuantFormat.QOperator,
                      op_types_to_quantize=list(v.ops) if v.ops else None,
                      per_channel=True, activation_type=act, weight_type=q.QuantType.QInt8,
                      nodes_to_exclude=exclude, calibrate_method=method, extra_options=extra)
    return target


def session(path: Path, opt_level: str = "all", threads: int = 2):
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    if not ORT_SPINNING:
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    options.graph_optimization_level = {
        "all": ort.GraphOptimizationLevel.ORT_ENABLE_ALL,
        "extended": ort.GraphOptimizationLevel.ORT_ENABLE_EXTENDED,
        "basic": ort.GraphOptimizationLevel.ORT_ENABLE_BASIC}[opt_level]
    options.log_severity_level = 3
    return ort.InferenceSession(str(path), sess_options=options,
                                providers=["CPUExecutionProvider"])


# --------------------------------------------------------------------------- speed


def speed(sessions: dict, inputs: dict, reps: int) -> dict[str, list[tuple[float, float]]]:
    """(best, median) ms per call for every shape, variants alternating call by call."""
    times = {(n, s): [] for n in sessions for s in inputs}
    for s, x in inputs.items():
        for sess in sessions.values():  # warm-up
            sess.run(None, {sess.get_inputs()[0].name: x})
        for _ in range(reps):
            for n, sess in sessions.items():
                feed = {sess.get_inputs()[0].name: x}
                t0 = time.perf_counter()
                sess.run(None, feed)
                times[(n, s)].append(1e3 * (time.perf_counter() - t0))
    return {n: [(min(times[(n, s)]), statistics.median(times[(n, s)])) for s in inputs]
            for n in sessions}


def kernel_profile(path: Path, x: np.ndarray, runs: int = 20) -> dict[str, float]:
    """Milliseconds per call spent in each operator type (onnxruntime's profiler), with the
    detector's session options."""
    import json

    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = 2
    options.inter_op_num_threads = 1
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    options.log_severity_level = 3
    with tempfile.TemporaryDirectory() as tmp:
        options.enable_profiling = True
        options.profile_file_prefix = str(Path(tmp) / "profile")
        sess = ort.InferenceSession(str(path), sess_options=options,
                                    providers=["CPUExecutionProvider"])
        feed = {sess.get_inputs()[0].name: x}
        for _ in range(runs):
            sess.run(None, feed)
        with open(sess.end_profiling()) as fh:
            events = json.load(fh)
    by_op: dict[str, float] = {}
    for e in events:
        if e.get("cat") == "Node" and e["name"].endswith("_kernel_time"):
            op = e["args"]["op_name"]
            by_op[op] = by_op.get(op, 0.0) + e["dur"] / runs / 1e3  # us -> ms per call
    return dict(sorted(by_op.items(), key=lambda kv: -kv[1]))


# --------------------------------------------------------------------------- accuracy


def detections(detector, frames) -> dict[str, np.ndarray]:
    """Boxes (N, 4) and scores of every frame by the full default detector."""
    out = {}
    for name, image, *_ in frames:
        dets = detector.detect(image)
        out[name] = (np.array([d.box_px for d in dets], float).reshape(-1, 4),
                     np.array([d.score for d in dets], float))
    return out


def agreement(ref: dict, got: dict, names: list[str]) -> dict:
    """Edge differences (got - ref) [px] of boxes matched at IoU >= 0.5, and unmatched counts."""
    diffs, ious, dscore, only_ref, only_got = [], [], [], 0, 0
    for n in names:
        (rb, rs), (gb, gs) = ref[n], got[n]
        pairs, ur, ug = match(1.0 - iou_matrix(rb, gb), 0.5)
        only_ref += len(ur)
        only_got += len(ug)
        if pairs:
            r, g = np.array(pairs).T
            diffs.append(gb[g] - rb[r])
            ious.extend(iou_matrix(rb, gb)[r, g])
            dscore.extend(gs[g] - rs[r])
    d = np.concatenate(diffs) if diffs else np.zeros((0, 4))
    return {"n": len(d), "only_ref": only_ref, "only_got": only_got,
            "iou": float(np.median(ious)) if ious else float("nan"),
            "abs_med": float(np.median(np.abs(d))) if len(d) else float("nan"),
            "abs_med_edges": np.median(np.abs(d), axis=0) if len(d) else np.full(4, np.nan),
            "signed_mean": d.mean(axis=0) if len(d) else np.full(4, np.nan),
            "signed_med": np.median(d, axis=0) if len(d) else np.full(4, np.nan),
            "p90_bottom": float(np.percentile(np.abs(d[:, 3]), 90)) if len(d) else float("nan"),
            "dscore": float(np.mean(dscore)) if dscore else float("nan")}


def build_all(variants: list[str], fp32: Path, out_dir: Path, reader: Reader) -> dict[str, Path]:
    """Weights of every variant, built into ``out_dir`` (FP32 variants: the copy itself)."""
    # per-channel QDQ needs DequantizeLinear's axis (opset 13); the export is opset 11
    opset13 = out_dir / "opset13.onnx"
    onnx.save(version_converter.convert_version(onnx.load(str(fp32)), QDQ_OPSET), opset13)
    pre = out_dir / "preprocessed.onnx"
    quant_pre_process(opset13, pre, skip_symbolic_shape=True)  # no sympy in the venv
    paths = {}
    for n in variants:
        t0 = time.perf_counter()
        paths[n] = build(n, VARIANTS[n], fp32, pre, out_dir, reader)
        if VARIANTS[n].kind != "fp32":
            print(f"built {n} in {time.perf_counter() - t0:.1f} s "
                  f"({paths[n].stat().st_size / 1e6:.1f} MB)", flush=True)
    return paths


def print_speed(paths: dict[str, Path], sessions: dict, fp32_det, video: Path, reps: int) -> None:
    frame = raw_frames(video, [HELDOUT_FRAMES.start])[0][1]
    h, w = frame.shape[:2]
    blobs = {b.shape: b for b in (fp32_det._prepare(frame[y1:y2, x1:x2])[0]
                                  for x1, y1, x2, y2 in tile_windows(w, h))}
    inputs = {s: np.stack([blobs[s[1:]]] * s[0]) for s in SHAPES}
    res = speed(sessions, inputs, reps)
    print(f"\nms per call (best / median of {reps}, variants alternating), "
          f"per keyframe = calls {CALLS_PER_KEYFRAME} of the shapes, from the medians")
    print(f"{'variant':18s}" + "".join(f"{'x'.join(map(str, s)):>18s}" for s in SHAPES)
          + f"{'keyframe':>10s}{'x fp32':>8s}")
    ref = sum(c * m for c, (_, m) in zip(CALLS_PER_KEYFRAME, res["fp32"], strict=True))
    for n, row in res.items():
        kf = sum(c * m for c, (_, m) in zip(CALLS_PER_KEYFRAME, row, strict=True))
        print(f"{n:18s}" + "".join(f"{b:8.1f} / {m:6.1f} " for b, m in row)
              + f"{kf:9.1f} {ref / kf:7.2f}")
    print("\nkernel time per operator type at 1x3x416x416 [ms per call, 20 calls]")
    for n in ("fp32", "qdq-u8"):
        if n in paths:
            prof = kernel_profile(paths[n], inputs[SHAPES[2]])
            print(f"  {n:8s} total {sum(prof.values()):5.1f}: " + ", ".join(
                f"{op} {ms:.1f}" for op, ms in list(prof.items())[:8]))


def _signed(values) -> str:
    return " ".join(f"{x:+5.2f}" for x in values)


def print_accuracy(sessions: dict, fp32_det, data: Path, video: Path) -> None:
    tracking = kitti_tracking_frames(data / "kitti_tracking")
    sets = {"kitti-raw-heldout": raw_frames(video, HELDOUT_FRAMES),
            "kitti-tracking": [(n, im) for n, im, _ in tracking],
            "tri-dgp": dgp_frames(data / "tri_dgp_front")}
    every = [f for frames in sets.values() for f in frames]
    results = {}
    for n, sess in sessions.items():
        if VARIANTS[n].opt_level != "all":
            continue  # same weights as fp32: same boxes
        det = copy.copy(fp32_det)  # the default detector with this variant's session
        det.session = sess
        results[n] = detections(det, every)
    print("\nrecall / precision on the six labelled KITTI tracking frames "
          "(default detector, score >= 0.3)")
    for n, res_n in results.items():
        total = MatchCounts(0, 0, 0, 0)
        for name, _, labels in tracking:
            boxes, scores = res_n[name]
            dets = [Detection(tuple(b), float(s), "car")
                    for b, s in zip(boxes, scores, strict=True)]
            total = total + score_against_kitti(dets, labels)
        print(f"  {n:18s} recall {total.recall:.3f} ({total.n_found}/{total.n_targets}) "
              f"precision {total.precision:.3f} ({total.n_false} false of "
              f"{total.n_detections})")
    print("\nagreement with FP32 (variant - FP32, frame px; edges x1 y1 x2 y2, y2 = bottom)")
    for set_name, frames in sets.items():
        names = [f[0] for f in frames]
        print(f" {set_name} ({len(names)} frames)")
        for n, res_n in results.items():
            if n == "fp32":
                continue
            a = agreement(results["fp32"], res_n, names)
            print(f"  {n:18s} matched {a['n']:3d} fp32-only {a['only_ref']:2d} "
                  f"new {a['only_got']:2d} IoU med {a['iou']:.3f} |d| med "
                  f"{a['abs_med']:.2f} (edges {_signed(a['abs_med_edges'])}) signed mean "
                  f"[{_signed(a['signed_mean'])}] median [{_signed(a['signed_med'])}] "
                  f"|d bottom| p90 {a['p90_bottom']:.2f} score {a['dscore']:+.3f}")


def main() -> None:
    here = Path(__file__).resolve().parents[1]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=here.parent / "shared")
    parser.add_argument("--reps", type=int, default=25, help="timed calls per shape and variant")
    parser.add_argument("--variants", nargs="+", default=list(DEFAULT_VARIANTS),
                        choices=list(VARIANTS), help="default: %(default)s")
    parser.add_argument("--no-speed", action="store_true")
    parser.add_argument("--no-accuracy", action="store_true")
    parser.add_argument("--keep", type=Path, help="build the variants here and keep them")
    args = parser.parse_args()
    if "fp32" not in args.variants:
        args.variants.insert(0, "fp32")
    data = args.shared / "data"
    video = data / "kitti_raw_0001" / "video.mp4"
    for needed in (video, data / "kitti_tracking", args.shared / "models"):
        if not needed.exists():
            print(f"error: {needed}: not found (the real data and the detector weights are in "
                  "../shared beside the repository; give --shared DIR)", file=sys.stderr)
            raise SystemExit(2)
    fp32_det = load_detector("yolox-nano", args.shared / "models", small_object_mode=True)
    fp32 = dynamic_copy(fp32_det.model_path)
    calib = [b for _, im in raw_frames(video, CALIB_FRAMES) for b in windows_of(fp32_det, im)]
    print(f"FP32 weights {fp32}; calibration {len(calib)} windows of KITTI raw 0001 frames "
          f"{CALIB_FRAMES.start}-{CALIB_FRAMES.stop - 1} every {CALIB_FRAMES.step}")
    with tempfile.TemporaryDirectory() as tmp:
        out_dir = args.keep or Path(tmp)
        out_dir.mkdir(parents=True, exist_ok=True)
        paths = build_all(args.variants, fp32, out_dir, Reader(fp32_det.input_name, calib))
        sessions = {n: session(paths[n], VARIANTS[n].opt_level) for n in args.variants}
        if not args.no_speed:
            print_speed(paths, sessions, fp32_det, video, args.reps)
        if not args.no_accuracy:
            print_accuracy(sessions, fp32_det, data, video)


if __name__ == "__main__":
    main()
