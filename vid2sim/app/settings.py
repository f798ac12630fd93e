"""The typed settings tree of a run: one record composed of the stages' own config classes.

Every command takes a :class:`Settings`; the CLI builds it from its options once, and
``vid2sim batch`` hands the same record to each row. Defaults live in the stage config
classes and in :mod:`vid2sim.base.defaults`, never in the CLI.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from vid2sim.adas.score import ScoreConfig
from vid2sim.adas.sensor import SensorConfig
from vid2sim.base.defaults import EGO_RATE_HZ
from vid2sim.base.errors import ImpossibleValueError
from vid2sim.calib.calibconfig import CalibrationConfig
from vid2sim.calib.sync import SyncConfig
from vid2sim.detect.lanes.markings import LaneMarkingConfig
from vid2sim.detect.lanes.track import LaneTrackConfig
from vid2sim.detect.rail import RailConfig
from vid2sim.detect.ranging import RangingConfig
from vid2sim.detect.schedule import ScheduleConfig
from vid2sim.detect.tracking.flow import FlowConfig
from vid2sim.detect.tracking.tracker import TrackerConfig
from vid2sim.detect.vehicles.models import DEFAULT_DETECTOR
from vid2sim.evaluate.frames_config import FrameSampleConfig
from vid2sim.evaluate.replayconfig import ReplayVideoConfig
from vid2sim.export.assemble import AssembleConfig
from vid2sim.export.commonroad import CommonRoadConfig
from vid2sim.export.events import EventConfig
from vid2sim.export.layout_config import LayoutConfig
from vid2sim.geo.lateral_config import LateralConfig
from vid2sim.geo.match_config import MatchConfig
from vid2sim.geo.trace import TraceParams


@dataclass(frozen=True, slots=True)
class DetectorSettings:
    """How vehicles are found in the frames.

    :param name: detector registry name (``vid2sim models list``) or a path to an .onnx file
    :param model_dir: folder searched first for registry weights (then ``$VID2SIM_MODEL_DIR``,
        then the user cache)
    :param tiles: also run on two half-frame tiles and a centre window (distant cars)
    :param refine: lead candidates re-detected on a crop per frame; None = the detector's
        default (1 with tiles, 0 without)
    :param score: minimum score to start a track [0-1]; None = the tracker's default
    :param detect_every: run the detector on every N-th frame (the tracker predicts between);
        above 1 it replaces the keyframe schedule
    :param keyframe_s: longest time between detector keyframes [s]; between them optical
        flow carries the boxes (:mod:`vid2sim.detect.schedule`); 0 = every frame
    :param threads: onnxruntime intra-op threads (a batch gives each job cores / jobs). 1:
        the keyframe schedule runs the net in two threads at once (the grid's keyframes in
        a worker thread ahead, the tracks' second looks in the main one, see
        :mod:`vid2sim.detect.frameloop`), each on a core of its own; a 416x416 YOLOX-nano window
        costs 12.5 ms of CPU on one thread and 15.2 ms on two, with no wall time gained on
        this shared 2-core machine (docs/performance.md)
    """

    name: str = DEFAULT_DETECTOR
    model_dir: Path | None = None
    tiles: bool = True
    refine: int | None = None
    score: float | None = None
    detect_every: int = 1
    keyframe_s: float = ScheduleConfig().keyframe_s
    threads: int = 1

    def check(self) -> None:
        """Raise :class:`InputError` for values no run can use."""
        if self.detect_every < 1:
            raise ImpossibleValueError(None, f"--detect-every must be >= 1, got {self.detect_every}")
        if self.score is not None and not 0.0 < self.score < 1.0:
            raise ImpossibleValueError(None, f"--score must be between 0 and 1, got {self.score}")
        if self.refine is not None and self.refine < 0:
            raise ImpossibleValueError(None, f"--refine must be >= 0, got {self.refine}")
        if self.threads < 1:
            raise ImpossibleValueError(None, f"threads must be >= 1, got {self.threads}")
        if not 0.0 <= self.keyframe_s <= 10.0:
            raise ImpossibleValueError(None, f"--keyframe-s must be 0-10 s, got {self.keyframe_s:g}")

    def schedule(self, base: ScheduleConfig | None = None) -> ScheduleConfig | None:
        """The keyframe schedule (``base`` with this ``keyframe_s``), or None when the
        detector runs on every ``detect_every``-th frame."""
        if self.detect_every > 1 or self.keyframe_s <= 0:
            return None
        return replace(base or ScheduleConfig(), keyframe_s=self.keyframe_s)

    def label(self) -> str:
        """How the boxes were made, for summaries (``yolox-nano + tiles``)."""
        return f"{self.name}{' + tiles' if self.tiles else ''}"


@dataclass(frozen=True, slots=True)
class SegmentConfig:
    """How segments are joined into one drive.

    :param max_gap_s: largest gap [s] between one segment's end and the next one's start for
        them to be one drive: dash-cams restart recording within a second; 2 s more covers
        the 1 s resolution of ``creation_time`` (a measurement of no camera: a bound)
    :param max_overlap_s: largest overlap [s] tolerated (clock resolution) before the order
        is refused
    """

    max_gap_s: float = 3.0
    max_overlap_s: float = 1.5



def tracker_for_score(base: TrackerConfig, score: float | None) -> TrackerConfig:
    """The tracker thresholds for a user's minimum start score (``--score``).

    Detections at or above ``score`` start and confidently continue tracks; weaker ones down
    to the tracker's low score only continue them.
    """
    if score is None:
        return base
    return replace(base, high_score=score, new_track_score=min(0.99, score + 0.05),
                   low_score=min(base.low_score, score))


@dataclass(frozen=True, slots=True)
class Settings:
    """Everything a run may be told besides its inputs: one tree that reaches every stage's
    config class. ``vid2sim ... --config settings.yaml`` changes any branch of it
    (:mod:`vid2sim.app.settings_file`), ``vid2sim settings`` prints it, and a build writes it
    whole into ``scenario.json`` (``source.settings``).

    :param detector: detector and detection schedule (the options ``--detector``, ``--score``...)
    :param schedule: the keyframe schedule's other numbers (``detector.keyframe_s`` sets its
        interval)
    :param flow: optical flow that carries boxes between keyframes
    :param tracker: tracker thresholds (``detector.score`` adjusts them, see
        :meth:`tracker_config`)
    :param markings: lane-marking measurement in each frame
    :param lanes: the lane track over the clip (re-run with the ego's GPS speed before the ego
        is placed across the road)
    :param rail: which tracks are trams
    :param ranging: monocular ranging priors and noise; lane and lead assignment
    :param trace: GPS smoothing
    :param matching: map matching
    :param lateral: the ego's lateral position from the lane markings
    :param assemble: scenario assembly
    :param layout: the road's cross-section and the parked cars' strips
    :param events: lane-change events
    :param frames: the report's sampled frames
    :param segments: how the segments of a split recording are joined into one drive
    :param sensor: the camera error model of ``test-policy`` (its ``level`` is
        ``--sensor-noise``)
    :param commonroad: the CommonRoad export's goal region and header
    :param score: thresholds and weights of test-policy's episode score
    :param calibration: camera self-calibration (priors, noise, frame sampling)
    :param sync: the GPS-video time sync (grids, noise floors, the clock rate's bound)
    :param camera_cache: keep and reuse self-calibrations per camera (frame size, rate,
        codec) as the prior of that camera's later clips
    :param rate_hz: ego trajectory sample rate [Hz]
    :param allow_download: fetch OpenStreetMap data for a trace without a map file
    :param osm_cache_dir: where downloaded maps are cached (default the user cache)
    :param progress: progress bars on stderr
    :param replay: how replay videos are drawn and encoded
    :param render_replay: ``build --render``: also write the replay video (replay.mp4)
    """

    detector: DetectorSettings = field(default_factory=DetectorSettings)
    schedule: ScheduleConfig = field(default_factory=ScheduleConfig)
    flow: FlowConfig = field(default_factory=FlowConfig)
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    markings: LaneMarkingConfig = field(default_factory=LaneMarkingConfig)
    lanes: LaneTrackConfig = field(default_factory=LaneTrackConfig)
    rail: RailConfig = field(default_factory=RailConfig)
    ranging: RangingConfig = field(default_factory=RangingConfig)
    trace: TraceParams = field(default_factory=TraceParams)
    matching: MatchConfig = field(default_factory=MatchConfig)
    lateral: LateralConfig = field(default_factory=LateralConfig)
    assemble: AssembleConfig = field(default_factory=AssembleConfig)
    layout: LayoutConfig = field(default_factory=LayoutConfig)
    events: EventConfig = field(default_factory=EventConfig)
    frames: FrameSampleConfig = field(default_factory=FrameSampleConfig)
    segments: SegmentConfig = field(default_factory=SegmentConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    commonroad: CommonRoadConfig = field(default_factory=CommonRoadConfig)
    score: ScoreConfig = field(default_factory=ScoreConfig)
    calibration: CalibrationConfig = field(default_factory=CalibrationConfig)
    sync: SyncConfig = field(default_factory=SyncConfig)
    camera_cache: bool = True
    rate_hz: float = EGO_RATE_HZ
    allow_download: bool = True
    osm_cache_dir: Path | None = None
    progress: bool = True
    replay: ReplayVideoConfig = field(default_factory=ReplayVideoConfig)
    render_replay: bool = False

    def tracker_config(self) -> TrackerConfig:
        """The tracker's thresholds with ``detector.score`` applied."""
        return tracker_for_score(self.tracker, self.detector.score)

    def layout_config(self) -> LayoutConfig:
        """The cross-section layout with this tree's assembly settings (the layout re-assembles
        the actors it moves onto their strips with them)."""
        return replace(self.layout, assemble=self.assemble)

    def schedule_config(self) -> ScheduleConfig | None:
        """The keyframe schedule with ``detector.keyframe_s``, or None (see
        :meth:`DetectorSettings.schedule`)."""
        return self.detector.schedule(self.schedule)

    def check(self) -> None:
        """Raise :class:`InputError` for settings no run can use (before any work)."""
        self.detector.check()
        if not 0.1 <= self.rate_hz <= 100.0:
            raise ImpossibleValueError(None, f"--rate must be 0.1-100 Hz, got {self.rate_hz:g}")

    def recorded(self, detector_used: bool = True) -> dict:
        """The options that change a scenario, as recorded in its ``source.options`` (the
        whole tree is ``source.settings``, :func:`vid2sim.app.settings_file.settings_tree`).

        Not recorded: where weights or caches are, thread counts, progress bars (they change
        how fast a scenario is made, not what it holds), nor the detector's settings when the
        boxes were imported (``detector_used`` False).
        """
        d = self.detector
        out = {"detect_every": d.detect_every, "score": d.score, "rate_hz": self.rate_hz,
               "allow_download": self.allow_download}
        if detector_used:
            out.update({"detector": d.name, "tiles": d.tiles, "refine": d.refine,
                        "keyframe_s": d.keyframe_s})
        return out
