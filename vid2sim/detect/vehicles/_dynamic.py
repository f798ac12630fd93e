"""A copy of fixed-shape detector weights whose input batch (and, where the graph allows, height
and width) is dynamic, cached beside the user's downloaded weights.

The shared exports take exactly one 416x416 image. Two things are cheaper with free dimensions:
several windows of a frame (tiles, crops) in one onnxruntime call, and a wide frame run at its
own aspect (1242x374 KITTI is 416x128 after scaling, a quarter of the letterboxed 416x416
canvas's pixels, all of which the net computes). The conversion only edits the graph's shape
metadata: the input and output dimensions become symbolic and every Reshape whose target
starts with the fixed batch of 1 takes the batch from its input instead (ONNX Reshape's 0 =
"copy this dimension"). The copy is checked against the original on a random input (batch 1
and batch 2) before it is used; a graph it cannot convert is used as it is.

The original weights are never modified; the copy lives in ``<model cache>/converted/`` under
a name keyed by the original's sha256 and :data:`CONVERSION_VERSION`.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from vid2sim.base.fileio import sha256_file, write_bytes_atomic
from vid2sim.detect.vehicles.models import cache_dir

log = logging.getLogger(__name__)

CONVERSION_VERSION = 1
"""Bumped whenever the conversion changes, so old cached copies are not reused."""

MAX_ABS_DIFF = 1e-3
"""Largest output difference between the copy and the original on the check input (scores
are 0-1 and box logits a few units; batched kernels may round differently)."""


def converted_dir() -> Path:
    """Folder of converted copies (``<model cache>/converted``)."""
    return cache_dir() / "converted"


def dynamic_copy(model_path: Path, cache: Path | None = None) -> Path | None:
    """Path of a dynamic-batch copy of ``model_path`` (made and checked on first use), or
    None when the ``onnx`` package is missing or the graph cannot be converted."""
    model_path = Path(model_path)
    cache = Path(cache) if cache is not None else converted_dir()
    digest = sha256_file(model_path)[:16]
    target = cache / f"{model_path.stem}.{digest}.dyn{CONVERSION_VERSION}.onnx"
    if target.is_file():
        return target
    try:
        import onnx  # optional heavy dependency: only for the first load of new weights
    except ImportError:
        log.info("onnx not installed: %s runs one window per call", model_path.name)
        return None
    try:
        data = _convert(onnx, model_path)
        target.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(target, data)
        if not _same_outputs(model_path, target):
            target.unlink()
            return None
    except Exception as exc:  # noqa: BLE001 - a graph this rewrite cannot read: keep the original
        log.info("cannot make %s dynamic (%s): one window per call", model_path.name, exc)
        target.unlink(missing_ok=True)
        return None
    return target


def _convert(onnx, model_path: Path) -> bytes:
    from onnx import numpy_helper  # part of the optional onnx package imported above

    model = onnx.load(str(model_path))
    graph = model.graph
    initializers = {t.name: t for t in graph.initializer}
    constants = {n.output[0]: n for n in graph.node if n.op_type == "Constant"}
    for node in graph.node:
        if node.op_type != "Reshape":
            continue
        name = node.input[1]
        if name in initializers:
            tensor = initializers[name]
        elif name in constants:
            tensor = constants[name].attribute[0].t
        else:
            continue
        shape = numpy_helper.to_array(tensor).copy()
        if shape.ndim == 1 and len(shape) > 0 and shape[0] == 1:
            shape[0] = 0  # take the batch from the input
            tensor.CopyFrom(numpy_helper.from_array(shape, tensor.name))
    graph_inputs = {t.name for t in graph.initializer}
    for value in graph.input:
        if value.name in graph_inputs:
            continue  # weights listed as inputs (PicoDet's export)
        dims = value.type.tensor_type.shape.dim
        for i, label in ((0, "batch"), (2, "height"), (3, "width")):
            if i < len(dims):
                dims[i].ClearField("dim_value")
                dims[i].dim_param = label
    for k, value in enumerate(graph.output):
        dims = value.type.tensor_type.shape.dim
        for i in range(len(dims) - 1):  # the last dimension is the channels: fixed
            dims[i].ClearField("dim_value")
            dims[i].dim_param = f"out{k}_{i}"
    del graph.value_info[:]  # stale fixed shapes of intermediate tensors
    return model.SerializeToString()


def _same_outputs(original: Path, copy: Path) -> bool:
    import onnxruntime as ort  # heavy native library: loaded with the detector anyway

    def session(path: Path):
        options = ort.SessionOptions()
        options.log_severity_level = 3
        return ort.InferenceSession(str(path), sess_options=options,
                                    providers=["CPUExecutionProvider"])

    a, b = session(original), session(copy)
    spec = a.get_inputs()[0]
    shape = [d if isinstance(d, int) else 1 for d in spec.shape]
    rng = np.random.default_rng(0)
    x = rng.uniform(0.0, 1.0, shape).astype(np.float32)
    ref = a.run(None, {spec.name: x})
    got = b.run(None, {spec.name: x})
    pair = b.run(None, {spec.name: np.concatenate([x, x[:, ::-1].copy()])})
    second = a.run(None, {spec.name: x[:, ::-1].copy()})
    for r, g, p, s in zip(ref, got, pair, second, strict=True):
        if r.shape != g.shape or np.abs(r - g).max() > MAX_ABS_DIFF:
            return False
        if np.abs(p[:1] - r).max() > MAX_ABS_DIFF or np.abs(p[1:] - s).max() > MAX_ABS_DIFF:
            return False
    return True
