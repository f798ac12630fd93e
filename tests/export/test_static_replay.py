"""Parked cars replay standing still: ``vid2sim build`` on KITTI raw 0001 (video, OXTS,
camera; real detector) and the speeds of the actors where the drive's parked cars stand (5-11 m
left of the ego, within 45 m ahead). Skips without ../shared."""

from __future__ import annotations

from vid2sim.app.build import build
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.core import scenario as scenario_io
from vid2sim.evaluate.ranging.static import replayed_static_speeds


def test_kitti_raw_parked_cars_replay_standing(kitti_raw_dir, model_dir, tmp_path):
    settings = Settings(detector=DetectorSettings(model_dir=model_dir), allow_download=False,
                        progress=False)
    result = build(Inputs(video=kitti_raw_dir / "video.mp4", gps=kitti_raw_dir,
                          camera=kitti_raw_dir / "camera.yaml"), tmp_path / "k", settings)
    rs = replayed_static_speeds(scenario_io.load(result.files["scenario"]))
    print(f"\nparked cars: {len(rs.per_actor)} actors, median speed {rs.median_speed_mps:.2f} "
          f"m/s, bias along the ego {rs.bias_mps:+.2f} m/s; per actor "
          + ", ".join(f"{k} {v[1]:.2f}" for k, v in sorted(rs.per_actor.items())))
    # Issue 13's bar: median speed <= 0.5 m/s (1.42 m/s, bias +1.04 m/s, before it).
    assert len(rs.per_actor) >= 6  # the row of cars parked on the left
    assert rs.median_speed_mps <= 0.5
    assert abs(rs.bias_mps) <= 0.5
