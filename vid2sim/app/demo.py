"""``vid2sim demo``: generate the embedded sample drive, then build and evaluate it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from vid2sim.app.build import BuildResult, build
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import Settings
from vid2sim.base.errors import InputError
from vid2sim.detect.vehicles.models import resolve_model
from vid2sim.samples.demo_sample import generate_demo_sample, helsinki_pbf_path


def run_demo(out_dir: Path, *, seed: int = 7, settings: Settings | None = None,
             force_detections: bool = False,
             report: Callable[[str], None] | None = None) -> BuildResult:
    """Generate the synthetic Helsinki sample into ``out_dir/sample`` and build + evaluate it
    into ``out_dir/build``.

    Runs the real detector where weights are found (``settings.detector.model_dir``,
    ``$VID2SIM_MODEL_DIR``, the user cache); otherwise, or with ``force_detections``, it
    imports the sample's noisy detection file and says so.
    """
    settings = settings or Settings()
    say = report or (lambda _msg: None)
    out_dir = Path(out_dir)
    say(f"generating the demo sample (seed {seed}) in {out_dir / 'sample'} ...")
    sample = generate_demo_sample(out_dir / "sample", seed=seed)
    say(f"  {sample.n_frames} frames {sample.width}x{sample.height} at {sample.fps:g} fps, "
        f"{sample.n_keyframes} keyframes, rendered in {sample.render_s:.1f} s")
    detector = settings.detector
    use_detections = force_detections
    if not use_detections:
        try:
            resolve_model(detector.name, model_dir=detector.model_dir)
        except InputError as exc:
            say(f"no detector weights ({exc}); using the sample's noisy detection file "
                f"{sample.detections.name} instead (pass --model-dir or set VID2SIM_MODEL_DIR "
                "to run the real detector)")
            use_detections = True
    if use_detections and force_detections:
        say(f"using the sample's noisy detection file {sample.detections.name} (--use-detections)")
    if not use_detections:
        say(f"running the real detector {detector.name} on the rendered frames")
    inputs = Inputs(video=sample.video, gps=sample.gps, map=helsinki_pbf_path(),
                    camera=sample.camera,
                    detections=sample.detections if use_detections else None,
                    keyframes=sample.keyframes)
    result = build(inputs, out_dir / "build", replace(settings, allow_download=False),
                   report=say)
    say(result.summary())
    return result
