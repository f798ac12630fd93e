"""Fixtures of the batch tests: a short demo sample with bad rows beside it, a Ray runtime."""

from __future__ import annotations

from pathlib import Path

import pytest

from vid2sim.app.settings import Settings

#: Length of the test clips [s]: long enough for a lead, keyframes and every build stage,
#: short enough that a build takes a few seconds on a shared 2-core machine.
CLIP_S = 5.0

#: The acceptance manifest: two valid rows, a broken video, a GPS file without fixes.
MANIFEST = ("video,name,gps,camera,detections,keyframes\n"
            "demo.mp4,full,demo.gpx,camera.yaml,detections.txt,keyframes.json\n"
            "demo.mp4,plain,,,detections.txt,\n"
            "broken.mp4,bad,,,detections.txt,\n"
            "demo.mp4,nogps,nofix.gpx,camera.yaml,detections.txt,\n")


@pytest.fixture(scope="session")
def clip(tmp_path_factory) -> Path:
    """A 5 s demo sample (imported detections: no weights needed), a truncated copy of its
    video, a GPX file without fixes, and :data:`MANIFEST` over them."""
    from vid2sim.samples.demo_sample import generate_demo_sample

    folder = tmp_path_factory.mktemp("clip")
    sample = generate_demo_sample(folder, seed=7, duration_s=CLIP_S)
    assert sample.video.name == "demo.mp4", "the manifests name demo.mp4"
    # The first kilobyte of a real video: OpenCV cannot open it, build raises an InputError.
    (folder / "broken.mp4").write_bytes(sample.video.read_bytes()[:1000])
    (folder / "nofix.gpx").write_text(
        '<?xml version="1.0"?>\n<gpx version="1.1" creator="test" '
        'xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg></trkseg></trk></gpx>\n',
        encoding="utf-8")
    (folder / "manifest.csv").write_text(MANIFEST, encoding="utf-8")
    return folder


@pytest.fixture(scope="session")
def ray_runtime():
    """A local Ray runtime with 2 CPUs for the whole session (starting one takes 5-15 s)."""
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'vid2sim[ray]')")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


def offline() -> Settings:
    """Settings of every test batch: no map download, no progress bars."""
    return Settings(allow_download=False, progress=False)
