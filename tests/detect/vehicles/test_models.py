"""Model registry: where weights are looked for, and checksum-verified download (no network:
file:// URLs and a local HTTP server on 127.0.0.1)."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import http.server
import threading

import pytest

from vid2sim.base.errors import FormatError, InputError, MissingInputError
from vid2sim.detect.vehicles import models


@pytest.fixture
def isolated(monkeypatch, tmp_path):
    """No env model dir, user cache in tmp."""
    monkeypatch.delenv(models.MODEL_DIR_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    return tmp_path


def test_registry_entries():
    assert set(models.MODELS) == {"yolox-nano", "picodet-s"}
    yolox = models.MODELS["yolox-nano"]
    assert yolox.sha256 == "e8af074932d4ed7e232278e3055cefcdea3edf178874a3694ae292649fb464dd"
    assert yolox.filename == "yolox_nano.onnx" and yolox.decoder == "yolox"
    assert "Megvii-BaseDetection/YOLOX/releases" in yolox.url
    pico = models.MODELS["picodet-s"]
    assert pico.sha256 == "cdab77bdde16e4f76bec734c4e5791801d1739e4c7ec1995e0e110e04300d0c2"
    assert pico.input_size_px == (416, 416) and pico.decoder == "picodet"


def test_resolve_search_order(isolated, monkeypatch):
    cache = models.cache_dir()
    env_dir, opt_dir = isolated / "env", isolated / "opt"
    for d in (cache, env_dir, opt_dir):
        d.mkdir(parents=True)
        (d / "yolox_nano.onnx").write_bytes(b"x")
    monkeypatch.setenv(models.MODEL_DIR_ENV, str(env_dir))
    assert models.resolve_model("yolox-nano", opt_dir) == opt_dir / "yolox_nano.onnx"
    assert models.resolve_model("yolox-nano") == env_dir / "yolox_nano.onnx"
    monkeypatch.delenv(models.MODEL_DIR_ENV)
    assert models.resolve_model("yolox-nano") == cache / "yolox_nano.onnx"
    explicit = isolated / "mine.onnx"
    explicit.write_bytes(b"y")
    assert models.resolve_model(str(explicit)) == explicit


def test_resolve_missing_names_the_fix(isolated):
    with pytest.raises(MissingInputError, match="models pull picodet-s") as err:
        models.resolve_model("picodet-s", isolated / "nowhere")
    assert models.MODEL_DIR_ENV in str(err.value)
    with pytest.raises(MissingInputError, match="absent.onnx"):
        models.resolve_model(str(isolated / "absent.onnx"))
    with pytest.raises(FormatError, match="resnet"):  # not a detector's name
        models.resolve_model("resnet")


@pytest.fixture
def fake_spec(monkeypatch, tmp_path):
    """A registry entry whose 'upstream' is a local file with a known checksum."""
    payload = b"pretend ONNX weights " * 1000
    src = tmp_path / "upstream" / "fake.onnx"
    src.parent.mkdir()
    src.write_bytes(payload)
    spec = dataclasses.replace(models.MODELS["yolox-nano"], name="fake", filename="fake.onnx",
                               url=src.as_uri(), sha256=hashlib.sha256(payload).hexdigest(),
                               also_accepted_sha256=())
    monkeypatch.setitem(models.MODELS, "fake", spec)
    return spec, src


def test_pull_verifies_and_installs(fake_spec, tmp_path):
    _spec, src = fake_spec
    dest = models.pull("fake", tmp_path / "models", progress=False)
    assert dest == tmp_path / "models" / "fake.onnx"
    assert dest.read_bytes() == src.read_bytes()
    assert [p.name for p in dest.parent.iterdir()] == ["fake.onnx"]  # no temp left


def test_pull_rejects_a_bad_checksum_and_leaves_nothing(fake_spec, tmp_path, monkeypatch):
    spec, _src = fake_spec
    monkeypatch.setitem(models.MODELS, "fake", dataclasses.replace(spec, sha256="0" * 64))
    dest_dir = tmp_path / "models"
    with pytest.raises(InputError, match="checksum mismatch"):
        models.pull("fake", dest_dir, progress=False)
    assert list(dest_dir.iterdir()) == []


def test_pull_over_local_http_and_network_errors(fake_spec, tmp_path):
    _spec, src = fake_spec
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(src.parent))
    handler.log_message = lambda *a, **k: None
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        base = f"http://127.0.0.1:{server.server_address[1]}"
        dest = models.pull("fake", tmp_path / "http", url=f"{base}/fake.onnx", progress=False)
        assert models.MODELS["fake"].accepts(hashlib.sha256(dest.read_bytes()).hexdigest())
        with pytest.raises(InputError, match="download failed"):
            models.pull("fake", tmp_path / "http2", url=f"{base}/missing.onnx", progress=False)
    finally:
        server.shutdown()
        server.server_close()


def test_shared_weights_match_the_registry(model_dir):
    from vid2sim.base.fileio import sha256_file

    for spec in models.MODELS.values():
        path = model_dir / spec.filename
        if not path.exists():
            pytest.skip(f"{path} absent")
        assert sha256_file(path) == spec.sha256
