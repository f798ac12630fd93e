"""vid2sim test-policy end to end: outputs, variations, the pool, written variants, bad input,
and summary.html rendered by headless Chromium."""

from __future__ import annotations

import csv
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET

import cv2
import numpy as np
import pytest

from vid2sim.base.errors import FormatError, ImpossibleValueError, InputError
from vid2sim.cli import main
from vid2sim.core.scenario import load, save
from vid2sim.samples.scenarios import braking_lead_scenario

GRID = "lead_decel=1:2:3,gap=0.6:1:3"


@pytest.fixture()
def scenario_dir(tmp_path):
    root = tmp_path / "builds"
    save(braking_lead_scenario(), root / "curve_a" / "scenario.json")
    save(braking_lead_scenario(duration_s=10.0), root / "curve_b" / "scenario.json")
    return root


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_a_grid_over_a_folder_of_scenarios(scenario_dir, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["test-policy", str(scenario_dir), "--policy", "log", "--vary", GRID,
                 "--out", str(out), "--jobs", "1"]) == 0
    summary = capsys.readouterr().out
    assert "18 episodes on 2 scenario(s)" in summary
    rows = _rows(out / "results.csv")
    assert len(rows) == 18
    assert {r["scenario"] for r in rows} == {str(scenario_dir / "curve_a"),
                                             str(scenario_dir / "curve_b")}
    by = {(r["scenario"].rsplit("/", 1)[-1], r["variation"]): r for r in rows}
    # the recorded driver brakes as logged: fine as recorded, into the lead when it brakes
    # twice as hard (its log does not react)
    assert by[("curve_a", "lead_decel=1 gap=1")]["collision"] == "0"
    assert by[("curve_a", "lead_decel=2 gap=1")]["collision"] == "1"
    assert by[("curve_a", "lead_decel=2 gap=1")]["terminated_by"] == "collision with lead"
    # closer start, same braking: the lead starts 0.4 x 25.55 m closer along its (the ego's)
    # lane, so the smallest gap is that much smaller
    gap_06 = float(by[("curve_a", "lead_decel=1 gap=0.6")]["min_gap_m"])
    gap_10 = float(by[("curve_a", "lead_decel=1 gap=1")]["min_gap_m"])
    assert gap_10 - gap_06 == pytest.approx(0.4 * 25.55, abs=0.2)
    html = (out / "summary.html").read_text()
    assert "Variations" in html and "Gap, TTC and speed over time" in html
    assert html.count("alt='heat map") == 2 and html.count("alt='time plots") == 2
    assert not re.search(r"(https?:)?//[a-z]",
                         re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", html))


def test_the_pool_gives_the_same_results_as_one_process(scenario_dir, tmp_path):
    outs = []
    for jobs in ("1", "2"):
        out = tmp_path / f"out{jobs}"
        assert main(["-q", "test-policy", str(scenario_dir / "curve_a"), "--policy", "aeb",
                     "--sensor-noise", "1", "--vary", "lead_decel=1.5/2.5,gap=0.8",
                     "--jobs", jobs, "--out", str(out)]) == 0
        outs.append((out / "results.csv").read_text())
    assert outs[0] == outs[1]
    assert "fcw@" in outs[0]


def test_noise_levels_and_impossible_grid_points(scenario_dir, tmp_path):
    path = scenario_dir / "curve_a" / "scenario.json"
    out = tmp_path / "out"
    assert main(["-q", "test-policy", str(path), "--policy", "acc+aeb", "--vary",
                 "noise=0/2,gap=-0.5:1:4", "--out", str(out)]) == 0
    rows = {r["variation"]: r for r in _rows(out / "results.csv")}
    assert len(rows) == 8
    for noise in ("0", "2"):  # scales -0.5 and 0 cannot be: skipped, not an error
        assert rows[f"noise={noise} gap=-0.5"]["skip_reason"].startswith("initial gap of -12.8")
        assert rows[f"noise={noise} gap=0"]["skip_reason"] == "initial gap of 0.0 m (scale 0)"
        assert rows[f"noise={noise} gap=1"]["collision"] == "0"
    # the noisy camera changes what ACC sees, hence what it does
    assert rows["noise=0 gap=1"]["min_gap_m"] != rows["noise=2 gap=1"]["min_gap_m"]


def test_random_samples_and_noise_seeds(scenario_dir, tmp_path):
    path = scenario_dir / "curve_a" / "scenario.json"
    out = tmp_path / "noise"
    assert main(["-q", "test-policy", str(path), "--policy", "acc", "--sensor-noise", "1",
                 "--samples", "3", "--seed", "5", "--out", str(out)]) == 0
    rows = _rows(out / "results.csv")
    assert [r["variation"] for r in rows] == ["recorded"] * 3
    assert len({r["min_gap_m"] for r in rows}) == 3  # three noise seeds
    out2 = tmp_path / "random"
    assert main(["-q", "test-policy", str(path), "--policy", "acc", "--vary",
                 "lead_decel=1:3,ego_speed=-2:2", "--samples", "4", "--out", str(out2)]) == 0
    rows = _rows(out2 / "results.csv")
    assert len(rows) == 4 and all(r["variation"].startswith("lead_decel=") for r in rows)


def test_variants_are_written_with_their_parameters(scenario_dir, tmp_path):
    path = scenario_dir / "curve_a" / "scenario.json"
    out = tmp_path / "out"
    assert main(["-q", "test-policy", str(path), "--policy", "acc", "--vary",
                 "lead_decel=2,ego_speed=-20/1", "--write-scenarios", "--out", str(out)]) == 0
    rows = _rows(out / "results.csv")
    assert rows[0]["skip_reason"].startswith("negative ego speed") and rows[0]["min_ttc_s"] == ""
    folder = out / "scenarios" / "scenario.json" / "0001"
    assert not (out / "scenarios" / "scenario.json" / "0000").exists()  # skipped: not written
    varied = load(folder / "scenario.json")
    assert varied.ego.trajectory.speed[0] == pytest.approx(15.0)
    root = ET.parse(folder / "scenario.xosc").getroot()
    params = {p.get("name"): float(p.get("value"))
              for p in root.iter("ParameterDeclaration")}
    # every variation parameter is declared, the unvaried ones at their neutral values
    assert params == {"lead_decel": 2.0, "ego_speed": 1.0, "gap": 1.0, "cut_in": 0.0}
    assert (folder / "road.xodr").exists()


@pytest.mark.parametrize("args,error,datum", [
    (["--policy", "cruise"], FormatError, "cruise"),  # no such policy
    # a module that does not import: no named class says why
    (["--policy", "no_such_module_q:policy"], InputError, "no_such_module_q"),
    (["--policy", "vid2sim:__version__"], FormatError, "__version__"),  # not callable
    (["--policy", "acc", "--vary", "lead_decel=0.5:1.5"], FormatError, "lead_decel"),  # no N
    (["--policy", "acc", "--vary", "speed=1"], FormatError, "speed"),  # no such parameter
    (["--policy", "acc", "--vary", "gap=1:0:3"], ImpossibleValueError, "gap"),  # LO > HI
    (["--policy", "acc", "--sensor-noise", "-1"], ImpossibleValueError, "--sensor-noise"),
])
def test_bad_input_is_one_error_line_exit_2_and_nothing_written(scenario_dir, tmp_path, capsys,
                                                                  raised, args, error, datum):
    out = tmp_path / "never"
    code = main(["test-policy", str(scenario_dir), *args, "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: ") and datum in err[0]
    assert raised == [error]
    assert not out.exists()
    assert not list(tmp_path.glob(".never.*"))


def test_missing_scenario_is_an_input_error(tmp_path, capsys):
    code = main(["test-policy", str(tmp_path / "nope.json"), "--policy", "acc", "--out",
                 str(tmp_path / "o")])
    assert code == 2 and "no such file or folder" in capsys.readouterr().err


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


@pytest.mark.skipif(_chromium() is None, reason="no chromium binary on PATH "
                    "(apt-get install chromium)")
def test_summary_heat_map_renders_in_headless_chromium(scenario_dir, tmp_path):
    path = scenario_dir / "curve_a" / "scenario.json"
    out = tmp_path / "out"
    assert main(["-q", "test-policy", str(path), "--policy", "log", "--vary", GRID,
                 "--out", str(out)]) == 0
    shot = tmp_path / "shot.png"
    cmd = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           "--no-first-run", f"--user-data-dir={tmp_path / 'profile'}",
           "--enable-logging=stderr", "--v=0", "--hide-scrollbars",
           "--window-size=1280,1600", f"--screenshot={shot}", (out / "summary.html").as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert not [line for line in proc.stderr.splitlines() if ":CONSOLE" in line]
    img = cv2.imread(str(shot))
    assert img is not None and img.shape[:2] == (1600, 1280)
    assert img[:40].mean() < 80  # the dark header band

    def pixels(rgb):  # how many pixels have a colour (within the browser's scaling blur)
        bgr = np.array(rgb[::-1], float)
        return int((np.abs(img.astype(float) - bgr).max(axis=2) < 12).sum())

    # the collision map's cells: green (no collision) and red (collision), both present
    assert pixels((0x2E, 0x8B, 0x57)) > 2000
    assert pixels((0xC0, 0x39, 0x2B)) > 2000
