"""Episode videos of ``vid2sim test-policy --render``: what the policy did, from above.

Each chosen episode is run again (same variation, same seed: episodes are deterministic)
with an observer that draws every policy step as it happens and encodes it
(:mod:`vid2sim.evaluate.videoout`), so no episode is held in memory as pictures. A frame is

- the bird's-eye view of the simulated scene (:mod:`vid2sim.evaluate.birdseye`): the
  policy's ego, the recorded ego at the same time as a ghost outline (``log``), every other
  vehicle with its id, the lead (the environment's) red; a banner names a collision from the
  step it happens and an AEB stage for a few seconds after it triggers;
- under it the strip (:mod:`vid2sim.evaluate.timeline`): the gap to the lead and the speeds
  over the whole episode, the policy's against the recorded drive's (dashed), the TTC band,
  and ticks at the AEB stages and the collision.

Which episodes: ``worst`` (the one with a collision, else the smallest TTC, then gap),
``N`` (the N worst in that order) or ``all``; skipped variants are never rendered.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vid2sim.adas.episode import EpisodeResult, run_episode
from vid2sim.adas.registry import PolicySpec
from vid2sim.adas.sensor import SensorConfig
from vid2sim.adas.variations import apply_variation, label
from vid2sim.base.errors import ImpossibleValueError
from vid2sim.base.fileio import atomic_path
from vid2sim.core.scenario import Scenario
from vid2sim.evaluate.birdseye import BirdsEye, Mark, outlined_text
from vid2sim.evaluate.replayconfig import ReplayVideoConfig
from vid2sim.evaluate.scenetime import SceneClock
from vid2sim.evaluate.timeline import Moment, Plot, Strip, Trace
from vid2sim.evaluate.videoout import VideoOut
from vid2sim.export.highway import ReplayEnv
from vid2sim.export.highway.info import StepInfo

#: Size of an episode video's parts [px]: a bird's-eye view 60 m ahead at 8 px/m over a
#: strip tall enough for two plots.
EPISODE_VIEW_PX = (720, 600)
EPISODE_STRIP_PX = 220
_COLLISION_BGR, _AEB_BGR = (60, 60, 255), (0, 210, 255)
_RECORDED_BGR = (170, 170, 170)


@dataclass(frozen=True, slots=True)
class RenderChoice:
    """Which episodes to render: ``all``, or the ``worst`` N."""

    all: bool = False
    worst: int = 1


def parse_render(text: str) -> RenderChoice:
    """``worst``, ``all`` or a whole number N >= 1 (the N worst episodes)."""
    value = str(text).strip().lower()
    if value == "all":
        return RenderChoice(all=True)
    if value == "worst":
        return RenderChoice(worst=1)
    if value.isdigit() and int(value) >= 1:
        return RenderChoice(worst=int(value))
    raise ImpossibleValueError(None, f"--render must be worst, all or a number of episodes "
                               f">= 1, got {text!r}")


def severity(result: EpisodeResult) -> tuple:
    """Sort key, worst first: a collision, then the smallest TTC, then the smallest gap."""
    m = result.metrics
    return (not m.collision, m.min_ttc_s, m.min_gap_m)


def pick(results: Sequence[EpisodeResult | None], choice: RenderChoice) -> list[int]:
    """Indices of the episodes to render (run ones only), worst first."""
    run = [k for k, r in enumerate(results) if r is not None and r.metrics is not None]
    run.sort(key=lambda k: severity(results[k]))
    return run if choice.all else run[:choice.worst]


def episode_strip(result: EpisodeResult, recorded: EpisodeResult | None, width: int,
                  height: int, config: ReplayVideoConfig) -> Strip:
    """The strip of an episode: gap and speeds (policy against the recorded drive), TTC,
    the AEB stages and the collision."""
    s = result.series
    gap = [Trace("policy", s["t_s"], s["gap_m"], (90, 90, 255))]
    speed = [Trace("policy ego", s["t_s"], s["ego_speed_mps"], (80, 220, 80)),
             Trace("lead", s["t_s"], s["lead_speed_mps"], (0, 165, 255), "dots")]
    if recorded is not None:
        r = recorded.series
        gap.append(Trace("recorded", r["t_s"], r["gap_m"], _RECORDED_BGR, "dashed"))
        speed.append(Trace("recorded ego", r["t_s"], r["ego_speed_mps"], _RECORDED_BGR,
                           "dashed"))
    moments = [Moment(float(t), f"AEB {name}", _AEB_BGR) for t, name in result.events]
    if result.collision_t_s is not None:
        moments.append(Moment(result.collision_t_s, "COLLISION", _COLLISION_BGR))
    t = s["t_s"]
    return Strip(width, height, float(t[0]), float(t[-1]),
                 [Plot("gap [m]", gap), Plot("speed [m/s]", speed)],
                 (t, s["ttc_s"]), moments, config.strip)


class EpisodeDrawer:
    """The observer of a re-run episode: draws and encodes each step (module docstring)."""

    def __init__(self, scenario: Scenario, result: EpisodeResult,
                 recorded: EpisodeResult | None, out: VideoOut, title: str,
                 config: ReplayVideoConfig):
        w, h = EPISODE_VIEW_PX
        self.view = BirdsEye(scenario.roads, w, h, config.birdseye)
        self.strip = episode_strip(result, recorded, w, EPISODE_STRIP_PX, config)
        self.ghost = SceneClock(Scenario(scenario.origin, [], scenario.ego, [], {},
                                         scenario.source))
        self.ego_size = (scenario.ego.length_m, scenario.ego.width_m)
        self.aeb = sorted((float(t), str(n)) for t, n in result.events)
        self.out, self.title, self.config = out, title, config
        self.canvas = np.zeros((h + EPISODE_STRIP_PX, w, 3), np.uint8)
        self.crashed_with = ""

    def __call__(self, env, info: StepInfo) -> None:
        t = float(info.t_s)
        states = env.vehicle_states()
        ego, others = states[0], states[1:]
        lead = str(info.lead_id) if info.has_lead else ""
        if info.crashed and not self.crashed_with:
            self.crashed_with = str(info.collision_with) or "?"
        ghost, _ = self.ghost.at(t)
        marks = [Mark("log", *ghost.xyh, *self.ego_size, "ghost"),
                 Mark("ego", ego.x_m, ego.y_m, ego.heading_rad, ego.length_m, ego.width_m,
                      "ego")]
        marks += [Mark(v.id, v.x_m, v.y_m, v.heading_rad, v.length_m, v.width_m,
                       "lead" if v.id == lead else "actor") for v in others]
        h = EPISODE_VIEW_PX[1]
        view = self.view.draw((ego.x_m, ego.y_m, ego.heading_rad), marks, title=self.title)
        self._banner(view, t)
        self.canvas[:h] = view
        self.canvas[h:] = self.strip.draw(t, self._line(t, info))
        self.out.write(self.canvas)

    def _banner(self, img: np.ndarray, t: float) -> None:
        texts = []
        if self.crashed_with:
            texts.append((f"COLLISION with {self.crashed_with}", _COLLISION_BGR))
        texts += [(f"AEB {name} at {ta:.1f} s", _AEB_BGR) for ta, name in self.aeb
                  if 0 <= t - ta <= self.config.strip.event_show_s]
        y = img.shape[0] - 40
        for text, colour in texts:
            outlined_text(img, text, (img.shape[1] // 2 - 90, y), 0.8, colour)
            y -= 30

    @staticmethod
    def _line(t: float, info: StepInfo) -> str:
        parts = [f"t {t:5.1f} s", f"ego {float(info.ego_speed_mps):4.1f} m/s"]
        if info.has_lead:
            ttc = float(info.ttc_s)
            parts.append(f"lead {info.lead_id}: gap "
                         f"{float(info.gap_m):.1f} m"
                         + (f", TTC {ttc:.1f} s" if math.isfinite(ttc) else ""))
        else:
            parts.append("no lead")
        return "   ".join(parts)


def write_episode_video(path: Path, scenario: Scenario, result: EpisodeResult,
                        recorded: EpisodeResult | None, title: str,
                        rerun: Callable[[Callable], EpisodeResult], step_hz: float,
                        config: ReplayVideoConfig | None = None) -> int:
    """Re-run an episode through ``rerun(observer)`` and write its video to ``path``
    (atomically); returns the frames written."""
    cfg = config or ReplayVideoConfig()
    w, h = EPISODE_VIEW_PX
    with atomic_path(path) as tmp, VideoOut(tmp, w, h + EPISODE_STRIP_PX, step_hz,
                                            config=cfg.encoder) as out:
        rerun(EpisodeDrawer(scenario, result, recorded, out, title, cfg))
        frames = out.frames
    return frames


def render_episodes(folder: Path, entries, spec: PolicySpec, opts, episodes,
                    choice: RenderChoice, ego_path: Callable) -> dict[int, str]:
    """The videos of the chosen episodes of a campaign (``vid2sim.adas.campaign``), each
    re-run with its variation, sensor noise and seed, written as ``folder/episodes/NNNN.mp4``
    (NNNN: the episode's row in results.csv, from 0); ``{episode index: relative path}``.
    ``ego_path(entry)`` is the logged path a ``cut_in`` variation needs."""
    out: dict[int, str] = {}
    step_hz = float(ReplayEnv.default_config()["policy_frequency"])
    for k in pick([ep.result for ep in episodes], choice):
        ep = episodes[k]
        entry = entries[ep.scenario_index]
        path = ego_path(entry) if "cut_in" in ep.values else None
        varied, _ = apply_variation(entry.scenario, ep.values, entry.roles, path)
        level = float(ep.values.get("noise", opts.sensor_noise))

        def rerun(observer, varied=varied, seed=ep.seed, level=level):
            return run_episode(varied, spec, reactive=opts.reactive,
                               sensor=SensorConfig(level=level), seed=seed, observer=observer)

        rel = f"episodes/{k:04d}.mp4"
        name = Path(entry.name)
        where = name.parent.name if name.name == "scenario.json" and name.parent.name else name.name
        title = f"{where}, {label(ep.values)}: {spec.name}"
        write_episode_video(folder / rel, varied, ep.result, entry.recorded, title, rerun,
                            step_hz)
        out[k] = rel
    return out
