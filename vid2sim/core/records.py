"""Typed records that flow between the pipeline stages (one place for all data classes).

Frames and time bases are part of the names:
- ``t_utc_s``: seconds since the Unix epoch (UTC), the GPS clock;
- ``t_s``: seconds from the video's first frame, the scenario clock;
- ENU: local east-north-up metres about the scenario origin (x east, y north, z up);
- vehicle frame: x forward, y left, z up, metres, origin on the road below the camera;
- pixels: x right, y down, origin at the top-left corner of the image.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any, Self

import numpy as np

from vid2sim.core.vocabulary import (  # noqa: F401  part of the records' vocabulary
    RAIL_CATEGORIES,
    VEHICLE_CATEGORIES,
    VehicleCategory,
)

# --------------------------------------------------------------------------- notes

class NoteKind(str, Enum):
    """What a line for the user is."""

    #: a result may be wrong or an input looks odd: the user should look
    WARNING = "warning"
    #: a quantity estimated from the data, and from what
    ESTIMATE = "estimate"
    #: something assumed for lack of an input (recorded in the scenario's source)
    ASSUMPTION = "assumption"


class Note(str):
    """A line for the user that knows its kind.

    It is the line's text (a ``str``, so it prints, joins and searches like one) with a
    :class:`NoteKind`, so that stages hand back one list of notes and the application layer
    routes warnings to the summary and estimates and assumptions to the scenario's source
    without searching the text.
    """

    kind: NoteKind

    def __new__(cls, kind: NoteKind, text: str) -> Self:
        note = super().__new__(cls, text)
        note.kind = NoteKind(kind)
        return note

    def __reduce__(self):  # pickles (batch workers) keep the kind
        return (Note, (self.kind, str(self)))

    @staticmethod
    def warning(text: str) -> Note:
        return Note(NoteKind.WARNING, text)

    @staticmethod
    def estimate(text: str) -> Note:
        return Note(NoteKind.ESTIMATE, text)

    @staticmethod
    def assumption(text: str) -> Note:
        return Note(NoteKind.ASSUMPTION, text)


def notes_of(notes: list[str], kind: NoteKind) -> list[str]:
    """The notes of one kind; a plain ``str`` counts as a warning."""
    return [n for n in notes if getattr(n, "kind", NoteKind.WARNING) is kind]

# --------------------------------------------------------------------------- GPS


@dataclass(frozen=True, slots=True)
class GpsFix:
    """One GPS fix as a receiver reported it.

    :param t_utc_s: fix time, seconds since the Unix epoch (UTC)
    :param lat_deg: WGS-84 latitude [deg]
    :param lon_deg: WGS-84 longitude [deg]
    :param alt_m: ellipsoidal or MSL altitude as reported [m], None if absent
    :param speed_mps: reported ground speed [m/s], None if absent
    :param course_deg: reported course over ground [deg clockwise from north], None if absent
    :param accuracy_m: reported horizontal accuracy [m], None if absent
    """

    t_utc_s: float
    lat_deg: float
    lon_deg: float
    alt_m: float | None = None
    speed_mps: float | None = None
    course_deg: float | None = None
    accuracy_m: float | None = None


@dataclass(slots=True)
class GpsTrace:
    """Fixes of one file in time order, with what the reader learnt about the file.

    :param video_start_utc_s: the video's first-frame time on the GPS clock where the format
        records it (BDD ``startTime``, KITTI camera timestamps), else None
    :param n_skipped: records the reader could not use (bad checksum, no fix, unparsable)
    """

    fixes: list[GpsFix]
    format: str
    path: Path | None = None
    video_start_utc_s: float | None = None
    n_skipped: int = 0
    warnings: list[str] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class Origin:
    """Origin of the local ENU frame (WGS-84 degrees, ellipsoidal metres)."""

    lat: float
    lon: float
    alt: float = 0.0


@dataclass(slots=True)
class EgoTrack:
    """The smoothed ego trajectory, uniformly sampled, in the scenario clock and ENU frame.

    Arrays share one length. ``heading_rad`` is counter-clockwise from east.
    """

    origin: Origin
    t_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray
    speed_mps: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    z_m: np.ndarray | None = None


@dataclass(slots=True)
class TraceStats:
    """What ``smooth_ego`` did to a GPS trace (the ``vid2sim trace`` summary).

    :param n_fixes: fixes read; ``n_rejected`` of them were outliers, ``n_skipped`` records the
        reader could not use
    :param duration_s: time from first to last fix [s]
    :param distance_m: path length of the smoothed trajectory [m]
    :param gaps: (t_start_s, length_s) of gaps between accepted fixes, scenario clock [s]
    :param stationary: (t_start_s, t_end_s) of periods detected as stopped (speed exactly 0)
    :param time_alignment: how the scenario clock was tied to the GPS clock, in words
    :param t0_utc_s: GPS-clock time of scenario t 0 (the video's first frame) [s since epoch]
    :param first_fix_t_s: scenario time of the first fix [s]
    :param noise_m: one-sigma position noise the smoother used (estimated or reported) [m]
    :param assumptions: what the trajectory assumes where the fixes say nothing (inside long
        gaps), for the scenario's ``source.assumptions``
    """

    format: str
    n_fixes: int
    n_rejected: int
    n_skipped: int
    duration_s: float
    distance_m: float
    speed_mean_mps: float
    speed_max_mps: float
    gaps: list[tuple[float, float]]
    stationary: list[tuple[float, float]]
    warnings: list[str]
    time_alignment: str
    t0_utc_s: float
    first_fix_t_s: float
    noise_m: float
    rate_hz: float
    n_samples: int
    assumptions: list[str] = field(default_factory=list)


# --------------------------------------------------------------------------- detection


@dataclass(frozen=True, slots=True)
class VideoInfo:
    """What a video (or an image folder) is: frame size [px], rate [frames/s], frame count."""

    width: int
    height: int
    fps: float
    n_frames: int


@dataclass(frozen=True, slots=True, eq=False)
class Frame:
    """One frame of a streamed video.

    :param index: 0-based frame number in the source
    :param t_s: seconds from the first frame (container timestamps, else index / fps)
    :param image_bgr: HxWx3 uint8 BGR pixels, or None for a frame skipped undecoded
        (``iter_frames(every=N)`` decodes only every N-th frame)
    """

    index: int
    t_s: float
    image_bgr: np.ndarray | None


@dataclass(frozen=True, slots=True)
class Detection:
    """A box found in one frame. ``box_px`` = (x1, y1, x2, y2) in pixels."""

    box_px: tuple[float, float, float, float]
    score: float
    category: VehicleCategory


@dataclass(frozen=True, slots=True)
class TrackedBox:
    """One tracked vehicle in one frame (a row of ``detections.csv``)."""

    frame: int
    t_s: float
    track_id: int
    category: VehicleCategory
    score: float
    x1: float
    y1: float
    x2: float
    y2: float


@dataclass(frozen=True, slots=True)
class RangedBox(TrackedBox):
    """A tracked box with its position relative to the camera (a row of ``tracks.csv``).

    :param range_m: longitudinal distance from the camera to the vehicle's rear [m]
    :param lateral_m: lateral offset of the vehicle's centre, positive to the left [m]
    :param range_rate_mps: d(range)/dt, negative when closing [m/s]
    :param range_std_m: one-sigma uncertainty of ``range_m`` [m]
    :param width_m: estimated vehicle width [m]
    :param lane: the lane relative to the ego lane of the frame: 0 the ego lane, +1 the next
        to the left, -1 the next to the right, ... (:func:`vid2sim.core.lead.lane_name` names
        them); None where unknown or not yet assigned (:mod:`vid2sim.detect.assign`)
    :param lane_offset_m: the centre's offset from the ego lane's centre line at its range,
        positive left [m] (NaN where unknown)
    """

    range_m: float
    lateral_m: float
    range_rate_mps: float
    range_std_m: float
    is_lead: bool
    width_m: float = float("nan")
    lateral_rate_mps: float = float("nan")
    lane: int | None = None
    lane_offset_m: float = float("nan")


# --------------------------------------------------------------------------- lane markings


class MarkingKind(str, Enum):
    """What a line on the road is, as far as one frame (or a track of frames) can tell."""

    #: a continuous painted line
    SOLID = "solid"
    #: a broken painted line (dashes and gaps along the road)
    DASHED = "dashed"
    #: the edge of the road surface (kerb, verge): no road beyond it
    ROAD_EDGE = "road_edge"
    #: a line whose pattern could not be told (too short, occluded)
    UNKNOWN = "unknown"


@dataclass(frozen=True, slots=True)
class LaneBoundary:
    """One line on the road in the vehicle frame's ground plane (x forward, y left).

    The line is ``y(x) = offset_m + heading_rad * x + curvature_inv_m * x**2 / 2
    + curvature_rate_inv_m2 * x**3 / 6`` (the small-angle clothoid of lane-detection
    literature), valid over ``x_near_m..x_far_m``.

    :param offset_m: lateral offset of the line at x = 0, i.e. beside the camera's ground
        point, positive left [m]
    :param heading_rad: angle of the line to the vehicle's x axis, positive turning left [rad]
    :param curvature_inv_m: curvature at x = 0, positive bending left [1/m]
    :param kind: solid, dashed, road edge or unknown (:class:`MarkingKind` values)
    :param confidence: 0..1, from the length of line seen and the fit's scatter
    :param offset_std_m: one-sigma uncertainty of ``offset_m`` from the fit [m]
    :param x_near_m, x_far_m: nearest and farthest ground distance the line was seen at [m]
    :param seen_m: length of painted (or edge) line found along it [m]
    :param curvature_rate_inv_m2: change of curvature per metre ahead [1/m^2]
    """

    offset_m: float
    heading_rad: float
    curvature_inv_m: float
    kind: str = MarkingKind.UNKNOWN.value
    confidence: float = 0.0
    offset_std_m: float = float("nan")
    x_near_m: float = float("nan")
    x_far_m: float = float("nan")
    seen_m: float = 0.0
    curvature_rate_inv_m2: float = 0.0

    def y_at(self, x_m: float | np.ndarray) -> float | np.ndarray:
        """Lateral position of the line [m, positive left] at ground distance ``x_m``."""
        return (self.offset_m + self.heading_rad * x_m + 0.5 * self.curvature_inv_m * x_m * x_m
                + self.curvature_rate_inv_m2 * x_m ** 3 / 6.0)


@dataclass(frozen=True, slots=True)
class LaneObservation:
    """What one video frame shows of the ego lane and the lines beside it.

    :param frame: 0-based frame index; ``t_s`` its time on the scenario clock [s]
    :param left, right: the ego lane's boundaries (the nearest line on each side), None where
        not seen
    :param lane_width_m: distance between the two boundaries at x = 0 [m] (NaN unless both)
    :param ego_offset_m: the camera's ground point from the lane's middle, positive left [m]
        (NaN unless both boundaries are seen; :class:`LaneTrack` fills one-sided frames)
    :param lines_left, lines_right: further lines beyond each boundary, nearest first
    :param cost_ms: processing time of the frame [ms] (for the benchmark)
    """

    frame: int
    t_s: float
    left: LaneBoundary | None = None
    right: LaneBoundary | None = None
    lane_width_m: float = float("nan")
    ego_offset_m: float = float("nan")
    lines_left: tuple[LaneBoundary, ...] = ()
    lines_right: tuple[LaneBoundary, ...] = ()
    cost_ms: float = float("nan")

    @property
    def found(self) -> bool:
        """Both boundaries of the ego lane were seen."""
        return self.left is not None and self.right is not None


@dataclass(frozen=True, slots=True)
class LaneChange:
    """The ego (or an actor) crossing a lane boundary.

    :param t_s: time the boundary was crossed, scenario clock [s]
    :param from_lane, to_lane: lane indices before and after; in a :class:`LaneTrack` counted
        from the lane the clip starts in (0), +1 per lane to the left; in an
        :class:`EgoLateral` 0 is the rightmost lane in the travel direction
    """

    t_s: float
    from_lane: int
    to_lane: int

    def as_tuple(self) -> tuple[float, int, int]:
        return (self.t_s, self.from_lane, self.to_lane)


@dataclass(slots=True)
class LaneTrack:
    """The ego lane over a clip: per-frame lane measurements filtered in time.

    Arrays share one length, one entry per measured (decoded) frame. Lateral quantities are
    in the vehicle frame (positive left) [m]; NaN where nothing usable was seen nearby.

    :param frame, t_s: frame index and scenario time [s]
    :param found: both boundaries of the ego lane seen in the frame
    :param ego_offset_raw_m: the frame's own offset of the camera from its lane's middle
    :param ego_offset_m: the filtered offset from the middle of the lane the ego is in
    :param offset_std_m: one-sigma uncertainty of ``ego_offset_m``
    :param lateral_m: continuous lateral position from the middle of the clip's first lane,
        lane changes included (``ego_offset_m + lane * lane_width``)
    :param lane: lanes moved since the clip's first lane (+1 one lane to the left)
    :param lane_width_m: filtered lane width
    :param heading_rad: the lane's direction relative to the vehicle's x axis, positive left
    :param curvature_inv_m: the lane's curvature, positive bending left [1/m]
    :param left_kind, right_kind: the boundaries' kinds (:class:`MarkingKind` values), taken
        over the recent frames
    :param lines_left, lines_right: number of lines seen beyond each boundary
    :param lane_changes: the ego's crossings of a lane boundary, lanes as in ``lane``
    :param observations: the per-frame measurements the track was made from
    """

    frame: np.ndarray
    t_s: np.ndarray
    found: np.ndarray
    ego_offset_raw_m: np.ndarray
    ego_offset_m: np.ndarray
    offset_std_m: np.ndarray
    lateral_m: np.ndarray
    lane: np.ndarray
    lane_width_m: np.ndarray
    heading_rad: np.ndarray
    curvature_inv_m: np.ndarray
    left_kind: list[str] = field(default_factory=list)
    right_kind: list[str] = field(default_factory=list)
    lines_left: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    lines_right: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    lane_changes: list[LaneChange] = field(default_factory=list)
    observations: list[LaneObservation] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def detection_rate(self) -> float:
        """Share of measured frames where both ego-lane boundaries were seen."""
        return float(np.mean(self.found)) if len(self.found) else 0.0


@dataclass(slots=True)
class EgoLateral:
    """The ego's place across its road: lane markings fused with GPS
    (:func:`vid2sim.geo.lateral.fuse_lateral`).

    Arrays share the length of ``ego.t_s``.

    :param ego: the ego track with its lateral position corrected (positions, headings,
        lat/lon; times and speeds as before)
    :param lane: lane index per sample, 0 = the rightmost lane in the travel direction (on
        a road derived from the trajectory: counted from the lines the video shows right
        of the ego)
    :param offset_in_lane_m: the ego from the middle of its lane (between the markings'
        centres), positive left [m]; NaN where the markings were not measured
    :param offset_from_centerline_m: the corrected ego from the road's centerline, positive
        left [m] (NaN on a trajectory road, whose centerline is the ego path)
    :param correction_m: lateral shift applied to each sample, positive left [m]
    :param lane_width_m: the ego lane's width from the markings [m] (NaN where unknown)
    :param lane_changes: the ego's lane changes, lanes as in ``lane``
    :param lane_center_xy_m: (N, 2) ENU path of the middle of the lane the clip starts in,
        with the ego's wander and lane changes taken out: the reference line of a road
        built from the trajectory; None where not measured
    :param source: what placed the ego across the road: ``"lane markings + map"``, ``"lane
        markings (no map)"`` or ``"gps"``
    :param lanes: the lane track re-filtered with the ego's speed, if there was one
    :param notes: estimates and warnings for the summary
    """

    ego: EgoTrack
    lane: np.ndarray
    offset_in_lane_m: np.ndarray
    offset_from_centerline_m: np.ndarray
    correction_m: np.ndarray
    lane_width_m: np.ndarray
    lane_changes: list[LaneChange] = field(default_factory=list)
    lane_center_xy_m: np.ndarray | None = None
    source: str = "gps"
    lanes: LaneTrack | None = None
    notes: list[str] = field(default_factory=list)


@dataclass(slots=True)
class RangingResult:
    """What ``vid2sim.detect.ranging.range_tracks`` found for all tracks of one video.

    :param boxes: one ranged box per input box, in the input order
    :param pitch_deg_estimated: camera pitch that puts the horizon at ``horizon_y_px`` [deg,
        positive looks down]
    :param horizon_y_px: image row of the road's vanishing line used for ranging [px]
    :param horizon_source: "lane markings", "vehicle consistency" or "camera file"
    :param width_m_by_track: estimated width of each track's vehicle [m]
    :param warnings: :class:`Note` lines (warnings, estimates); ground_m_by_track: (height
        over the ego's road, spread [m], source) per track
    """

    boxes: list[RangedBox]
    pitch_deg_estimated: float
    horizon_y_px: float
    horizon_source: str
    width_m_by_track: dict[int, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    #: the ego lane measured from the lane markings while the frames streamed, if it was
    lanes: LaneTrack | None = None
    #: tracks never the lead whatever their lane (trams on their own bed, detect.rail)
    never_lead_tracks: frozenset[int] = frozenset()
    #: every streamed frame's time (index -> s, the container's clock; skipped frames absent)
    frame_times_s: dict[int, float] | None = None
    ground_m_by_track: dict[int, tuple[float, float, str]] = field(default_factory=dict)
    standing_tracks: frozenset[int] = frozenset()  # ranged from the ego's own motion


#: What an event is (scenario.json's ``events``, :mod:`vid2sim.core.scenario`).
EVENT_TYPES = ("cut_in", "cut_out", "lane_change")
#: The ego's id in events.
EGO_ID = "ego"


@dataclass(frozen=True, slots=True)
class Event:
    """A lane change seen in the video (the fields are those of scenario.json's ``events``, :mod:`vid2sim.core.scenario`)."""

    type: str
    actor: str
    t_s: float
    from_lane: int
    to_lane: int

    def to_json(self) -> dict[str, Any]:
        return {"type": self.type, "actor": self.actor, "t_s": float(self.t_s),
                "from_lane": int(self.from_lane), "to_lane": int(self.to_lane)}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Event:
        return cls(str(d["type"]), str(d["actor"]), float(d["t_s"]), int(d["from_lane"]),
                   int(d["to_lane"]))



# --------------------------------------------------------------------------- evaluation


@dataclass(frozen=True, slots=True)
class AnnotatedBox:
    """A human-drawn box on a keyframe.

    :param box_px: (x1, y1, x2, y2) in pixels
    :param category: the :class:`VehicleCategory` of a vehicle, or the source's own class
        name for an ignore region (KITTI "dontcare", "misc")
    :param id: the annotation's track/label id, None where the format has none
    :param range_m: longitudinal distance from the camera to the vehicle's near face [m]
        where the annotation carries 3D (KITTI), else None
    :param ignore: True for regions where a simulated box counts neither way (KITTI
        DontCare, crowd regions, vehicle classes the scenario does not model)
    """

    box_px: tuple[float, float, float, float]
    category: VehicleCategory | str
    id: str | None = None
    range_m: float | None = None
    ignore: bool = False


@dataclass(slots=True)
class Keyframe:
    """One annotated video frame.

    :param frame: 0-based frame index in the video (or image folder), None if unknown
    :param t_s: seconds from the video's first frame (the scenario clock)
    :param name: the frame's name in the annotation file (image name or frame number)
    """

    frame: int | None
    t_s: float
    name: str
    boxes: list[AnnotatedBox] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class ProjectedBox:
    """A simulated vehicle's 3D box projected into the camera image at one instant.

    :param box_px: (x1, y1, x2, y2) in pixels, clipped to the image
    :param range_m: longitudinal distance from the camera to the box's nearest point [m]
    :param hard: a box an annotator may legitimately skip (tiny, mostly outside the image,
        partly behind the camera or largely hidden): a match counts, no match is no FP
    """

    actor_id: str
    box_px: tuple[float, float, float, float]
    category: VehicleCategory
    range_m: float
    hard: bool = False


# --------------------------------------------------------------------------- road


@dataclass(slots=True)
class RoadResult:
    """The road stage's output (:func:`vid2sim.geo.roads.build_road`).

    :param roads: ``scenario.Road`` records in ENU about ``origin`` (normally one: the matched
        route as one centerline; ``lanes`` counts all lanes of the carriageway, the ego's
        direction has ``lanes_forward`` of them, on the right of the centerline)
    :param route_osm_way_ids: OSM way ids in travel order, consecutive repeats merged
    :param matches: one dict per input fix: ``t`` (scenario clock [s]), ``osm_way_id``
        (None where unmatched), ``offset_m`` (signed lateral offset of the raw fix from the
        matched way, positive left of travel [m], None where unmatched)
    :param ego_lane: lane index per ego sample, 0 = rightmost lane in the travel direction
    :param ego_offset_m: signed lateral offset of each ego sample from the centerline [m]
    :param source: ``"osm"`` or ``"trajectory"``
    :param stats: summary figures (fixes, matched_share, route_length_m, ways, lanes, ...)
    """

    origin: Origin
    roads: list  # list[vid2sim.core.scenario.Road]; scenario imports records, not the reverse
    route_osm_way_ids: list[int]
    matches: list[dict]
    ego_lane: np.ndarray
    ego_offset_m: np.ndarray
    source: str
    lanes_forward: int = 1
    stats: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    #: ENU polylines [m] of the drivable OSM ways near the trace, for pictures only
    map_polylines: list = field(default_factory=list)
    route_lines: list = field(default_factory=list)  # per road (route [m], span): cover_points
