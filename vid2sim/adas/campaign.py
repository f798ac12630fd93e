"""``vid2sim test-policy``: run a policy on scenarios and their variations, write the results.

:func:`run_campaign` checks every input first (policy, ``--vary``, scenario files), then runs
one episode per scenario and variation (in a process pool when there are several and
``jobs > 1``), and writes ``results.csv`` and ``summary.html`` (and, with
``write_scenarios``, each variant as ``scenario.json`` + OpenSCENARIO/OpenDRIVE) into a staging
folder beside the output folder, moved into place only when everything succeeded.
"""

from __future__ import annotations

import csv
import io
import math
import multiprocessing
import os
import shutil
import tempfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from vid2sim.adas.episode import EpisodeResult, run_episode
from vid2sim.adas.episode_metrics import COLUMNS as METRIC_COLUMNS
from vid2sim.adas.episodevideo import parse_render, render_episodes
from vid2sim.adas.registry import PolicySpec, describe, parse_policy
from vid2sim.adas.score import SCORE_COLUMNS, ScoreConfig
from vid2sim.adas.sensor import SensorConfig
from vid2sim.adas.summary import write_summary
from vid2sim.adas.variations import (
    LogRoles,
    apply_variation,
    find_roles,
    label,
    parse_vary,
    variations,
)
from vid2sim.base.errors import ImpossibleValueError, MissingInputError
from vid2sim.base.fileio import write_text_atomic
from vid2sim.core import scenario as scenario_io
from vid2sim.core.scenario import Scenario
from vid2sim.export.highway import ReplayEnv
from vid2sim.export.openscenario import write_openscenario

RESULT_COLUMNS = ("scenario", "policy", "variation", *METRIC_COLUMNS)
"""The columns results.csv starts with (the contract); extra columns follow them."""
EXTRA_COLUMNS = ("handovers", "handover_times_s", "aeb_events", "terminated_by", "skip_reason",
                 *SCORE_COLUMNS)


@dataclass(frozen=True)
class CampaignOptions:
    """Everything ``vid2sim test-policy`` was asked to do."""

    inputs: tuple[Path, ...]
    policy: str
    out_dir: Path
    reactive: bool = False
    sensor_noise: float = 0.0
    vary: str | None = None
    samples: int | None = None
    seed: int = 0
    jobs: int = 1
    write_scenarios: bool = False
    #: the camera error model (its ``level`` is ``sensor_noise`` or the varied noise)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    render: str | None = None
    """``worst``, ``all`` or N: episode videos of those episodes (episodes/*.mp4)."""
    score: ScoreConfig = field(default_factory=ScoreConfig)


@dataclass
class Episode:
    """One row of the campaign."""

    scenario_index: int
    values: dict[str, float]
    seed: int
    result: EpisodeResult | None = None


@dataclass
class ScenarioEntry:
    name: str
    path: Path
    scenario: Scenario
    roles: LogRoles | None = None
    recorded: EpisodeResult | None = None  # the log, for the plots


# --------------------------------------------------------------------------- inputs


def find_scenarios(inputs: tuple[Path, ...], out_dir: Path | None = None) -> list[tuple[str, Path]]:
    """``(name, path)`` of every scenario: files as given, folders searched for
    ``scenario.json`` (named by their folder relative to the given one)."""
    found: list[tuple[str, Path]] = []
    out_dir = Path(out_dir).resolve() if out_dir is not None else None
    for given in inputs:
        path = Path(given)
        if path.is_file():
            found.append((str(path), path))
        elif path.is_dir():
            hits = sorted(p for p in path.rglob("scenario.json")
                          if out_dir is None or out_dir not in p.resolve().parents)
            if not hits:
                raise MissingInputError(path, "holds no scenario.json", "give scenario files or "
                                        "folders with build outputs")
            for p in hits:
                rel = p.parent.relative_to(path)
                found.append((str(path / rel) if str(rel) != "." else str(path), p))
        else:
            raise MissingInputError(path, "no such file or folder")
    names = [n for n, _ in found]
    if len(set(names)) != len(names):
        seen: dict[str, int] = {}
        unique = []
        for n, p in found:
            seen[n] = seen.get(n, 0) + 1
            unique.append((n if seen[n] == 1 else f"{n} ({seen[n]})", p))
        found = unique
    return found


def _episode_seed(seed: int, index: int) -> int:
    return int(np.random.SeedSequence([int(seed) & 0xFFFFFFFF, index]).generate_state(1)[0])


# --------------------------------------------------------------------------- workers

_WORKER: dict = {}


def _init_worker(entries, spec, options) -> None:
    _WORKER.update(entries=entries, spec=spec, options=options)
    _WORKER["paths"] = {}


def _run(task: tuple[int, int, dict, int]) -> tuple[int, EpisodeResult]:
    index, scenario_index, values, seed = task
    entries, spec, opts = _WORKER["entries"], _WORKER["spec"], _WORKER["options"]
    entry = entries[scenario_index]
    result, _ = _episode(entry, spec, opts, values, seed, _WORKER["paths"])
    return index, result


def _ego_path(entry: ScenarioEntry, cache: dict):
    if entry.name not in cache:
        cache[entry.name] = ReplayEnv(entry.scenario, ego_mode="log").path
    return cache[entry.name]


def _episode(entry: ScenarioEntry, spec: PolicySpec, opts: CampaignOptions,
             values: dict[str, float], seed: int, paths: dict):
    """Apply the variation and run it: ``(result, varied scenario or None)``."""
    path = _ego_path(entry, paths) if "cut_in" in values else None
    varied, reason = apply_variation(entry.scenario, values, entry.roles, path)
    if varied is None:
        return EpisodeResult(None, skip_reason=reason), None
    level = values.get("noise", opts.sensor_noise)
    result = run_episode(varied, spec, reactive=opts.reactive,
                         sensor=replace(opts.sensor, level=float(level)), seed=seed,
                         score_config=opts.score)
    return result, varied


# --------------------------------------------------------------------------- the campaign


def run_campaign(opts: CampaignOptions, *, progress: bool = False) -> str:
    """Run the campaign of ``opts`` and write its outputs; returns a summary for the CLI."""
    spec = parse_policy(opts.policy)
    if opts.sensor_noise < 0 or not math.isfinite(opts.sensor_noise):
        raise ImpossibleValueError(None, f"--sensor-noise must be a finite level >= 0, got "
                                   f"{opts.sensor_noise}")
    if opts.samples is not None and opts.samples < 1:
        raise ImpossibleValueError(None, f"--samples must be >= 1, got {opts.samples}")
    axes = parse_vary(opts.vary, random=opts.samples is not None) if opts.vary else ()
    choice = parse_render(opts.render) if opts.render else None
    out_dir = Path(opts.out_dir)
    entries = [ScenarioEntry(name, path, scenario_io.load(path))
               for name, path in find_scenarios(opts.inputs, out_dir)]
    draws = variations(axes, opts.samples, opts.seed) if axes else (
        [{}] * (opts.samples or 1))
    for entry in entries:
        entry.roles = find_roles(entry.scenario) if axes else LogRoles(None, None, None, None,
                                                                       None)
        entry.recorded = run_episode(entry.scenario, PolicySpec("log", ego_mode="log"),
                                     score_config=opts.score)
    episodes = [Episode(si, dict(values), _episode_seed(opts.seed, k))
                for k, (si, values) in enumerate((si, v) for si in range(len(entries))
                                                  for v in draws)]
    varied = _run_all(entries, spec, opts, episodes, progress)

    out_dir.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    try:
        write_text_atomic(staging / "results.csv", results_csv(entries, spec, episodes))
        videos = (render_episodes(staging, entries, spec, opts, episodes, choice,
                                  lambda entry: _ego_path(entry, {}))
                  if choice is not None else {})
        write_summary(staging / "summary.html", entries=entries, spec=spec, episodes=episodes,
                      axes=axes, options=opts, videos=videos)
        if opts.write_scenarios:
            _write_variants(staging / "scenarios", entries, episodes, varied)
        out_dir.mkdir(parents=True, exist_ok=True)
        for child in staging.iterdir():
            target = out_dir / child.name
            if target.is_dir() and not target.is_symlink():
                shutil.rmtree(target)
            child.replace(target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return _summary(entries, spec, episodes, out_dir) + (
        f"\nwrote {len(videos)} episode video(s) into {out_dir / 'episodes'}" if videos else "")


def _run_all(entries, spec, opts, episodes, progress) -> dict[int, Scenario]:
    """Run every episode (a pool of ``opts.jobs`` processes when it pays); returns the varied
    scenarios by episode index when they are to be written."""
    from tqdm import tqdm  # the progress bar, as the other long commands

    varied: dict[int, Scenario] = {}
    jobs = max(1, min(int(opts.jobs or 1), len(episodes)))
    bar = tqdm(total=len(episodes), unit="episode", desc="test-policy", disable=not progress)
    try:
        if jobs == 1 or opts.write_scenarios:
            paths: dict = {}
            for ep in episodes:
                ep.result, sc = _episode(entries[ep.scenario_index], spec, opts, ep.values,
                                         ep.seed, paths)
                if sc is not None and opts.write_scenarios:
                    varied[id(ep)] = sc
                bar.update()
            return varied
        # fork: the workers inherit the loaded scenarios and any user policy module
        method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
        tasks = [(k, ep.scenario_index, ep.values, ep.seed) for k, ep in enumerate(episodes)]
        with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context(method),
                                 initializer=_init_worker, initargs=(entries, spec, opts)) as pool:
            for k, result in pool.map(_run, tasks, chunksize=1):
                episodes[k].result = result
                bar.update()
    finally:
        bar.close()
    return varied


def default_jobs() -> int:
    """Worker processes by default: the cores, at most 4 (episodes are single-threaded)."""
    return max(1, min(os.cpu_count() or 1, 4))


# --------------------------------------------------------------------------- outputs


def _number(value: float) -> str:
    if isinstance(value, bool | np.bool_):
        return "1" if value else "0"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return f"{value:.4f}".rstrip("0").rstrip(".") if value != 0 else "0"


def results_csv(entries: list[ScenarioEntry], spec: PolicySpec, episodes: list[Episode]) -> str:
    """results.csv: one row per episode, :data:`RESULT_COLUMNS` then :data:`EXTRA_COLUMNS`
    (the last of them the episode's score and its terms, :mod:`vid2sim.adas.score`; a term
    that does not apply, such as the speed limit where the map has none, is empty).

    Skipped variants have empty metric cells and their ``skip_reason``.
    """
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow([*RESULT_COLUMNS, *EXTRA_COLUMNS])
    for ep in episodes:
        r = ep.result
        row = [entries[ep.scenario_index].name, spec.name, label(ep.values)]
        if r is None or r.metrics is None:
            row += [""] * len(METRIC_COLUMNS) + ["", "", "", "", r.skip_reason if r else ""]
            row += [""] * len(SCORE_COLUMNS)
        else:
            m = r.metrics.as_dict()
            row += [_number(m[c]) for c in METRIC_COLUMNS]
            row += [str(len(r.handovers)),
                    ";".join(f"{h.actor_id}@{h.t_s:.2f}" for h in r.handovers),
                    ";".join(f"{name}@{t:.1f}" for t, name in r.events),
                    r.terminated_by, ""]
            score = r.score.as_row() if r.score is not None else {}
            row += [_number(score[c]) if c in score and not math.isnan(score[c]) else ""
                    for c in SCORE_COLUMNS]
        writer.writerow(row)
    return buf.getvalue()


def _write_variants(root: Path, entries, episodes, varied) -> None:
    for k, ep in enumerate(episodes):
        sc = varied.get(id(ep))
        if sc is None:
            continue
        name = Path(entries[ep.scenario_index].name).name or "scenario"
        folder = root / f"{name}" / f"{k:04d}"
        scenario_io.save(sc, folder / "scenario.json")
        params = {f"{key}": float(v) for key, v in ep.values.items()}
        write_openscenario(sc, folder, parameters=params)


def _summary(entries, spec, episodes, out_dir: Path) -> str:
    run = [ep.result for ep in episodes if ep.result is not None and ep.result.metrics]
    skipped = len(episodes) - len(run)
    collisions = sum(r.metrics.collision for r in run)
    handovers = sum(len(r.handovers) for r in run)
    lines = [f"{len(episodes)} episodes on {len(entries)} scenario(s) with {describe(spec)}: "
             f"{len(run)} run, {skipped} skipped, {collisions} with a collision"
             + (f", {handovers} actor handovers" if handovers else "")]
    if run:
        ttc = min(r.metrics.min_ttc_s for r in run)
        gap = min(r.metrics.min_gap_m for r in run)
        lines.append(f"smallest TTC {ttc:.2f} s, smallest gap {gap:.2f} m, largest deceleration "
                     f"{max(r.metrics.max_decel_mps2 for r in run):.1f} m/s^2")
        scores = [r.score.score for r in run if r.score is not None]
        if scores:
            lines.append(f"score (nuPlan-shaped, 0-1): mean {np.mean(scores):.2f}, lowest "
                         f"{min(scores):.2f}")
    lines.append(f"wrote {out_dir / 'results.csv'} and {out_dir / 'summary.html'}")
    return "\n".join(lines)
