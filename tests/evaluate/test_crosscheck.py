"""commonroad-crime's criticality measures on the CommonRoad export against test-policy's
figures for the ``log`` policy: equal where the definitions coincide, apart where they do not
(the figures by regime are in docs/commonroad.md)."""

from __future__ import annotations

import json
import math
import os
import subprocess
from pathlib import Path

import pytest

from vid2sim.adas.episode import run_episode
from vid2sim.adas.registry import parse_policy
from vid2sim.evaluate.crosscheck import by_regime, minima, pair_steps, regime
from vid2sim.samples.scenarios import BRAKING_LEAD, LATE_REACTION, braking_lead_scenario

SCRIPT = Path(__file__).resolve().parents[2] / ".ci" / "commonroad_crime.sh"


def test_regimes():
    assert regime(-4.0, -4.05) == "constant closing"
    assert regime(0.0, -4.0) == "lead braking"
    assert regime(-6.0, 0.0) == "ego braking"
    assert regime(1.0, 0.0) == "other"


def _crime(scenario, tmp_path: Path) -> dict:
    """Export with the ego as obstacle and run commonroad-crime in its own venv."""
    pytest.importorskip("commonroad.common.writer.file_writer_xml",
                        reason="commonroad-io is not installed (docs/commonroad.md)")
    from vid2sim.export.commonroad import write_commonroad

    venv = Path(os.environ.get("VID2SIM_CRIME_VENV", "/tmp/vid2sim-crimevenv"))
    if not (venv / "bin" / "python").exists():
        pytest.skip(f"no commonroad-crime venv at {venv} (create one with "
                    f".ci/commonroad_crime.sh OUT RESULT {venv})")
    write_commonroad(scenario, tmp_path, ego_as_obstacle=True)
    result = tmp_path / "crime.json"
    run = subprocess.run(["bash", str(SCRIPT), str(tmp_path), str(result), str(venv)],
                         capture_output=True, text=True, timeout=900, check=False)
    assert run.returncode == 0, run.stdout + run.stderr
    return json.loads(result.read_text())


@pytest.fixture(scope="module")
def late_reaction(tmp_path_factory):
    sc = braking_lead_scenario(**LATE_REACTION)
    crime = _crime(sc, tmp_path_factory.mktemp("crime"))
    log = run_episode(sc, parse_policy("log"))
    return pair_steps(crime, log.series, sc, "lead"), log


def test_ttc_and_headway_agree_where_the_definitions_coincide(late_reaction):
    """At constant closing speed crime's constant-acceleration TTC is gap / closing speed:
    within crime's 2-decimal rounding of vid2sim's at every step; its HW is the gap."""
    pairs, _ = late_reaction
    table = by_regime(pairs)
    steady = table["constant closing"]
    assert steady["both_finite"] >= 8  # 3.1-3.9 s: the gap closing at 8 m/s
    assert steady["max_abs_rel_diff"] <= 0.01
    for name in table:
        assert table[name]["max_hw_diff_m"] <= 0.02  # a straight road: HW is the gap


def test_smallest_ttc_within_5_percent_of_the_log_policy(late_reaction):
    """crime's smallest finite TTC within 5 % of test-policy's minimum TTC for ``log``: its
    smallest lies one step earlier (3.9 s against 4.0 s, 2.54 s against 2.44 s): at the step
    the braking begins crime's constant-acceleration TTC already sees it (and never meets the
    lead: inf)."""
    pairs, log = late_reaction
    ours, theirs = minima(pairs)
    assert ours == pytest.approx(log.metrics.min_ttc_s)
    assert math.isfinite(ours) and math.isfinite(theirs)
    assert abs(theirs - ours) / ours <= 0.05


def test_where_the_definitions_differ(late_reaction):
    """Braking phases: vid2sim's TTC stays finite while crime's constant-acceleration TTC is
    inf. Ego braking: the closing stops before contact (a real difference of models).
    Lead braking: commonroad-crime 0.4.5 takes the other vehicle's acceleration as a magnitude
    (``sqrt(a^2 + a_y^2) cos``): a braking lead counts as an accelerating one, so no collision
    is predicted (at 2.0 s the constant-acceleration TTC is 3.22 s, vid2sim's constant-speed
    one 8.39 s, crime's inf)."""
    pairs, _ = late_reaction
    table = by_regime(pairs)
    for name in ("lead braking", "ego braking"):
        assert table[name]["both_finite"] == 0  # within 10 s, crime's TTC is never finite
        assert table[name]["crime_inf_ours_finite"] >= 10
    at_2s = next(p for p in pairs if abs(p.t_s - 2.0) < 1e-6)
    assert at_2s.regime == "lead braking" and at_2s.crime_ttc_s == math.inf
    # the lead's constant-deceleration prediction: gap = dv t + a t^2 / 2
    dv, a = BRAKING_LEAD["speed_mps"] - 10.0, BRAKING_LEAD["decel_mps2"]  # 14 vs 10 m/s
    t_hit = (-dv + math.sqrt(dv * dv + 2 * a * at_2s.gap_m)) / a
    assert t_hit == pytest.approx(3.22, abs=0.01)  # 33.55 m closing at 4 m/s, +4 m/s^2
    assert t_hit < at_2s.ttc_s == pytest.approx(33.55 / 4.0, abs=0.01)


def test_time_headway_is_the_time_to_reach_the_leads_place(late_reaction):
    """crime's THW is the time the ego, on its logged path, takes to reach the lead's
    present rear; vid2sim's is gap / own speed: equal (to crime's 0.1 s steps) while the ego
    holds its speed to the lead's place, longer once it brakes on the way."""
    pairs, _ = late_reaction
    first = pairs[0]  # 35.55 m at 14 m/s, reached before the ego brakes at 4 s
    assert first.crime_thw_s == pytest.approx(math.ceil(first.thw_s * 10) / 10, abs=1e-9)
    at_3s = next(p for p in pairs if abs(p.t_s - 3.0) < 1e-6)
    # 27.55 m: 14 m to 4 s, then 6 m/s^2 down to 6 m/s (13.33 m), the rest at 6 m/s: 2.4 s
    assert at_3s.crime_thw_s == pytest.approx(2.4) and at_3s.thw_s == pytest.approx(1.97, 0.01)
