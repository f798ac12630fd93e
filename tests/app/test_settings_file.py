"""The settings tree as a file: every stage's numbers reachable, recorded whole, read back."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.test_cli_bad_inputs import CAMERA_YAML, gps_csv, mot_rows, write_video
from vid2sim.app.settings import Settings
from vid2sim.app.settings_file import (
    NOT_RECORDED,
    apply_settings,
    changed_settings,
    load_settings,
    settings_tree,
    settings_yaml,
)
from vid2sim.base.errors import FormatError, ImpossibleValueError
from vid2sim.cli import main
from vid2sim.core.tables import read_tracks_csv


def _leaves(tree: dict, where: str = "") -> dict[str, object]:
    out = {}
    for k, v in tree.items():
        name = f"{where}.{k}" if where else k
        out.update(_leaves(v, name) if isinstance(v, dict) else {name: v})
    return out


def _nest(dotted: dict[str, object]) -> dict:
    out: dict = {}
    for name, value in dotted.items():
        *parents, leaf = name.split(".")
        node = out
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    return out


def test_every_config_class_of_the_pipeline_is_in_the_tree():
    names = {f.name for f in dataclasses.fields(Settings)}
    for stage in ("detector", "schedule", "flow", "tracker", "markings", "lanes", "rail",
                  "ranging", "trace", "matching", "lateral", "assemble", "layout", "events",
                  "frames", "segments", "sensor"):
        assert stage in names
        assert dataclasses.is_dataclass(getattr(Settings(), stage))


def test_the_printed_defaults_read_back_as_the_defaults(tmp_path):
    path = tmp_path / "settings.yaml"
    path.write_text(settings_yaml(Settings()))
    assert load_settings(path) == Settings()
    assert changed_settings(load_settings(path)) == {}
    assert not any(name in _leaves(settings_tree(Settings())) for name in NOT_RECORDED)


_LEAVES = _leaves(settings_tree(Settings()))
_NUMERIC = sorted(n for n, v in _LEAVES.items()
                  if isinstance(v, float) and math.isfinite(v) and v > 0)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.sampled_from(_NUMERIC), min_size=1, max_size=6, unique=True),
       st.floats(1.01, 3.0))
def test_any_numbers_changed_in_a_file_are_what_the_tree_records(names, factor):
    wanted = {n: _LEAVES[n] * factor for n in names}
    changed = apply_settings(Settings(), _nest(wanted))
    leaves = _leaves(settings_tree(changed))
    for n, v in wanted.items():
        assert leaves[n] == v  # exact: not rounded on the way
    assert set(changed_settings(changed)) == set(wanted)
    # and the tree written as JSON (as scenario.json holds it) reads back the same
    assert apply_settings(Settings(), json.loads(json.dumps(settings_tree(changed)))) == changed


@pytest.mark.parametrize("text,error", [
    ("tracker:\n  high_scor: 0.5\n", FormatError),        # a typo names the setting
    ("trackers:\n  high_score: 0.5\n", FormatError),      # an unknown stage
    ("ranging:\n  lane_width_m: .nan\n", ImpossibleValueError),
    ("ranging:\n  lane_width_m: .inf\n", ImpossibleValueError),
    ("ranging:\n  lane_width_m: -3.5\n", ImpossibleValueError),  # a width is >= 0
    ("tracker:\n  min_hits: 2.5\n", ImpossibleValueError),       # a count is whole
    ("tracker:\n  min_hits: true\n", ImpossibleValueError),
    ("ranging:\n  per_frame_pitch: 1\n", ImpossibleValueError),  # a switch is true/false
    ("ranging:\n  priors:\n    van: {width_m: 2.0}\n", FormatError),  # no such category
    ("detector:\n  keyframe_s: 50\n", ImpossibleValueError),     # Settings.check
    ("detector:\n  threads: 4\n", FormatError),  # how fast, not what: not a file's to set
    ("- tracker\n", FormatError),
    ("tracker: [unclosed\n", FormatError),
])
def test_a_bad_settings_file_is_an_input_error_of_its_kind(tmp_path, text, error):
    path = tmp_path / "settings.yaml"
    path.write_text(text)
    with pytest.raises(error) as exc:
        load_settings(path)
    assert str(path) in str(exc.value)


def test_an_empty_file_is_the_defaults(tmp_path):
    path = tmp_path / "empty.yaml"
    path.write_text("")
    assert load_settings(path) == Settings()


def test_a_bad_settings_file_is_one_error_line_and_nothing_written(tmp_path, capsys):
    path = tmp_path / "settings.yaml"
    path.write_text("tracker:\n  high_scor: 0.5\n")
    gps = tmp_path / "gps.csv"
    gps.write_text(gps_csv())
    out = tmp_path / "ego.csv"
    assert main(["trace", str(gps), "--config", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "tracker.high_scor" in err[0]
    assert not out.exists()


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("cfg")
    files = {"video": write_video(d / "video.mp4"), "gps": d / "gps.csv",
             "det": d / "det.txt", "camera": d / "camera.yaml"}
    files["gps"].write_text(gps_csv())
    files["det"].write_text(mot_rows())
    files["camera"].write_text(CAMERA_YAML)
    return files


def _build(inputs, out, config=None):
    argv = ["-q", "build", str(inputs["video"]), "--gps", str(inputs["gps"]), "--camera",
            str(inputs["camera"]), "--detections", str(inputs["det"]), "--offline",
            "--out", str(out)]
    if config is not None:
        argv += ["--config", str(config)]
    assert main(argv) == 0
    return (json.loads((out / "scenario.json").read_text())["source"]["settings"],
            read_tracks_csv(out / "tracks.csv"))


def test_a_config_file_changes_a_tracker_and_a_ranging_number_of_a_build(inputs, tmp_path):
    base_tree, base_rows = _build(inputs, tmp_path / "default")
    assert base_tree == settings_tree(Settings(allow_download=False))
    # a tracker number: a track needs 1,000 hits before it counts, so none is confirmed
    tracker = tmp_path / "tracker.yaml"
    tracker.write_text(yaml.safe_dump({"tracker": {"min_hits": 1000}}))
    tree, rows = _build(inputs, tmp_path / "tracker", tracker)
    assert tree["tracker"]["min_hits"] == 1000
    assert base_rows and len(rows) < len(base_rows)
    # a ranging number: with cars 20 % wider than the prior, the width cue (one of the fit's
    # cues, beside the ground contact and the top edge) puts every car farther
    width = Settings().ranging.priors["car"].width_m
    ranging = tmp_path / "ranging.yaml"
    ranging.write_text(yaml.safe_dump({"ranging": {"priors": {"car": {"width_m": width * 1.2}}}}))
    tree, rows = _build(inputs, tmp_path / "ranging", ranging)
    assert tree["ranging"]["priors"]["car"]["width_m"] == pytest.approx(width * 1.2)
    ratio = [b.range_m / a.range_m for a, b in zip(base_rows, rows, strict=True)
             if math.isfinite(a.range_m) and math.isfinite(b.range_m)]
    assert ratio and min(ratio) >= 1.0 and sorted(ratio)[len(ratio) // 2] > 1.003
