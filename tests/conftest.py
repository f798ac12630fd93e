"""Shared fixtures: where the real data and the detector weights are, skipping when absent; the
demo build and the KITTI raw 0001 build (session-wide: the policy tests and the exporters'
tests share them)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

# Property tests run on shared 2-core machines: no per-example deadline (timing is for
# benchmarks/), and in CI a fixed example sequence so a run is reproducible.
settings.register_profile("vid2sim", deadline=None)
settings.register_profile("vid2sim-ci", deadline=None, derandomize=True)
settings.load_profile("vid2sim-ci" if os.environ.get("CI") else "vid2sim")

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("VID2SIM_SHARED", REPO.parent / "shared"))
DATA = SHARED / "data"
MODELS = Path(os.environ.get("VID2SIM_MODEL_DIR", SHARED / "models"))


def _need(path: Path, what: str) -> Path:
    if not path.exists():
        pytest.skip(f"{what} not found at {path} (set VID2SIM_SHARED to the shared folder)")
    return path


@pytest.fixture(scope="session")
def kitti_raw_dir() -> Path:
    """../shared/data/kitti_raw_0001: video, OXTS GPS/IMU, calibration."""
    return _need(DATA / "kitti_raw_0001", "KITTI raw drive 0001")


@pytest.fixture(scope="session")
def kitti_tracking_dir() -> Path:
    """../shared/data/kitti_tracking: labelled frames of sequences 0001 and 0016."""
    return _need(DATA / "kitti_tracking", "KITTI tracking labels and frames")


@pytest.fixture(scope="session")
def model_dir() -> Path:
    """Folder with yolox_nano.onnx and picodet_s_416_coco.onnx (never downloaded in tests)."""
    return _need(MODELS, "detector weights folder")


@pytest.fixture(scope="session", autouse=True)
def _private_cache_dir(tmp_path_factory):
    """Tests never read or write the user's cache (parsed maps, downloads): one temporary
    cache folder per test session (:func:`vid2sim.geo.mapcache.default_cache_dir`)."""
    saved = os.environ.get("VID2SIM_CACHE_DIR")
    os.environ["VID2SIM_CACHE_DIR"] = str(tmp_path_factory.mktemp("vid2sim-cache"))
    yield
    if saved is None:
        os.environ.pop("VID2SIM_CACHE_DIR", None)
    else:
        os.environ["VID2SIM_CACHE_DIR"] = saved


@pytest.fixture
def raised(monkeypatch) -> list[type]:
    """The classes of the input errors the CLI turned into its one ``error:`` line, in order:
    CLI tests check the class of the mistake, the line's format and the exit code."""
    from vid2sim.base.errors import InputError
    from vid2sim.cli.group import cli

    seen: list[type] = []
    run = cli.main

    def spy(*args, **kwargs):
        try:
            return run(*args, **kwargs)
        except InputError as exc:
            seen.append(type(exc))
            raise

    monkeypatch.setattr(cli, "main", spy)
    return seen


@pytest.fixture(scope="session")
def demo_scenario_path(tmp_path_factory):
    """``vid2sim demo --use-detections``: the build's scenario.json (about 10 s to make)."""
    from vid2sim.app.demo import run_demo  # the build stack, for the tests that need it
    from vid2sim.app.settings import Settings

    out = tmp_path_factory.mktemp("demo")
    run_demo(out, force_detections=True, settings=Settings(progress=False))
    return out / "build" / "scenario.json"


@pytest.fixture(scope="session")
def demo_scenario(demo_scenario_path):
    from vid2sim.core import scenario as scenario_io

    return scenario_io.load(demo_scenario_path)


@pytest.fixture(scope="session")
def kitti_scenario(tmp_path_factory, kitti_raw_dir, model_dir):
    """``vid2sim build`` of KITTI raw 0001 with its GPS and camera (real YOLOX-nano, every
    second frame as tests/test_pipeline.py; about a minute)."""
    from vid2sim.app.build import build
    from vid2sim.app.inputs import Inputs
    from vid2sim.app.settings import DetectorSettings, Settings
    from vid2sim.core import scenario as scenario_io

    out = tmp_path_factory.mktemp("kitti")
    settings = Settings(detector=DetectorSettings(model_dir=model_dir, detect_every=2),
                        allow_download=False, progress=False)
    result = build(Inputs(video=kitti_raw_dir / "video.mp4", gps=kitti_raw_dir,
                          camera=kitti_raw_dir / "camera.yaml"), out / "k", settings)
    return scenario_io.load(result.files["scenario"])
