"""Groups of whole tracks, so the ranging's per-box arrays exist for one group at a time.

Every step of the ranging after the horizon works per box (the single-frame fits) or per
track (sizes, the range filter); only the horizon, the per-frame body pitch and the
standing vehicles' ground look across tracks, and they need a few columns of all boxes.
The ranging therefore runs its per-box and per-track steps on groups of whole tracks of
about :data:`GROUP_BOXES` boxes each and keeps of a whole-clip fit only the columns the
cross-track steps read (:class:`FitColumns`): its memory no longer grows with the clip, and
the results are bitwise those of one whole-clip pass (each box is fitted on its own, each
track filtered on its own).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from vid2sim.core.records import TrackedBox
from vid2sim.detect.ranging.config import RangingConfig

#: Boxes per group of tracks (a track is never split; a longer one is a group of its own):
#: the fits' block (:data:`vid2sim.detect.ranging.boxfit.FIT_BLOCK_BOXES`), whose
#: temporaries are the ranging's peak memory.
GROUP_BOXES = 4096


@dataclass(frozen=True)
class TrackGroup:
    """Whole tracks ranged together: their boxes' indices into the clip's box list
    (``index``), and each track's boxes as positions into ``index`` (time order)."""

    index: np.ndarray
    tracks: dict[int, np.ndarray]


def track_groups(tracks: dict[int, np.ndarray], max_boxes: int | None = None
                 ) -> list[TrackGroup]:
    """Consecutive tracks (in ``tracks``' order) gathered into groups of at most
    ``max_boxes`` boxes each (default :data:`GROUP_BOXES`), or of one track where it alone
    has more."""
    max_boxes = GROUP_BOXES if max_boxes is None else max_boxes
    groups: list[TrackGroup] = []
    members: list[np.ndarray] = []
    tids: list[int] = []
    size = 0

    def close() -> None:
        starts = np.cumsum([0] + [m.size for m in members])
        groups.append(TrackGroup(np.concatenate(members), {
            t: np.arange(starts[k], starts[k + 1]) for k, t in enumerate(tids)}))

    for tid, m in tracks.items():
        if members and size + m.size > max_boxes:
            close()
            members, tids, size = [], [], 0
        members.append(m)
        tids.append(tid)
        size += m.size
    if members:
        close()
    return groups


@dataclass
class FitColumns:
    """The columns of a single-frame fit (:class:`~vid2sim.detect.ranging.boxfit.BoxFit`) that
    the steps looking across tracks read, for every box of the clip (NaN / False where not
    filled): what the per-frame pitch and the standing vehicles need, without the per-box
    covariance matrices."""

    range_m: np.ndarray
    lateral_m: np.ndarray
    valid: np.ndarray
    ground_ok: np.ndarray
    width_ok: np.ndarray

    @classmethod
    def empty(cls, n: int) -> FitColumns:
        return cls(np.full(n, np.nan), np.full(n, np.nan), np.zeros(n, dtype=bool),
                   np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))

    def put(self, index: np.ndarray, fit) -> None:
        """Fill the rows ``index`` from a fit of those boxes (in that order)."""
        for f in fields(self):
            getattr(self, f.name)[index] = getattr(fit, f.name)


@dataclass
class BoxSizes:
    """Per box: the class priors (``*0``) and what its track learnt (``w``, ``h``, with
    spreads), the road's spread under it, and its ground height; per track the widths."""

    w0: np.ndarray
    w0_std: np.ndarray
    h0: np.ndarray
    h0_std: np.ndarray
    l0: np.ndarray
    l0_std: np.ndarray
    w: np.ndarray
    w_std: np.ndarray
    h: np.ndarray
    h_std: np.ndarray
    road_std: np.ndarray
    road_z: np.ndarray
    width_by_track: dict[int, float] = field(default_factory=dict)

    @classmethod
    def from_priors(cls, boxes: list[TrackedBox], config: RangingConfig) -> BoxSizes:
        priors = [config.prior_for(b.category) for b in boxes]
        arr = {k: np.array([getattr(p, k) for p in priors], dtype=float)
               for k in ("width_m", "width_std_m", "height_m", "height_std_m", "length_m",
                         "length_std_m")}
        n = len(boxes)
        return cls(arr["width_m"], arr["width_std_m"], arr["height_m"], arr["height_std_m"],
                   arr["length_m"], arr["length_std_m"], arr["width_m"].copy(),
                   arr["width_std_m"].copy(), arr["height_m"].copy(),
                   arr["height_std_m"].copy(), np.full(n, config.road_height_std_m),
                   np.zeros(n))

    def subset(self, index: np.ndarray) -> BoxSizes:
        """The rows ``index`` (copies), with a width dictionary of their own."""
        return BoxSizes(*(getattr(self, k)[index] for k in SIZE_COLUMNS))

    def put(self, index: np.ndarray, part: BoxSizes) -> None:
        """The rows ``index`` and the widths learnt from a :meth:`subset` of them."""
        for k in SIZE_COLUMNS:
            getattr(self, k)[index] = getattr(part, k)
        self.width_by_track.update(part.width_by_track)


SIZE_COLUMNS = ("w0", "w0_std", "h0", "h0_std", "l0", "l0_std", "w", "w_std", "h", "h_std",
                "road_std", "road_z")


@dataclass
class RangeOutput:
    """Per box: what the range filter and the lateral smoother give (NaN where not)."""

    range_m: np.ndarray
    rate: np.ndarray
    lateral: np.ndarray
    lateral_rate: np.ndarray
    std: np.ndarray

    @classmethod
    def empty(cls, n: int) -> RangeOutput:
        return cls(*(np.full(n, np.nan) for _ in range(5)))

    def put(self, index: np.ndarray, part: RangeOutput) -> None:
        for k in ("range_m", "rate", "lateral", "lateral_rate", "std"):
            getattr(self, k)[index] = getattr(part, k)


def track_pieces(t_s: np.ndarray, valid: np.ndarray, max_gap_s: float, index: np.ndarray
                 ) -> list[np.ndarray]:
    """Split one time-ordered track (``index`` its boxes) into pieces that the range filter
    takes on their own: consecutive usable measurements more than ``max_gap_s`` apart start a
    new piece, each unusable box joins the piece of its nearest usable one in time, and boxes
    further than ``max_gap_s`` from any usable one form single-box pieces (their own fit)."""
    if not valid.any():
        return [index]
    seen = np.flatnonzero(valid)
    piece_of_seen = np.concatenate(([0], np.cumsum(np.diff(t_s[seen]) > max_gap_s)))
    # Nearest usable box in time for every box.
    pos = np.clip(np.searchsorted(t_s[seen], t_s), 1, seen.size - 1) if seen.size > 1 else (
        np.zeros(t_s.size, dtype=int))
    if seen.size > 1:
        left, right = seen[pos - 1], seen[pos]
        nearest = np.where(np.abs(t_s - t_s[left]) <= np.abs(t_s[right] - t_s), pos - 1, pos)
    else:
        nearest = pos
    label = piece_of_seen[nearest]
    far = np.abs(t_s - t_s[seen[nearest]]) > max_gap_s
    pieces = [index[(label == k) & ~far] for k in range(int(piece_of_seen[-1]) + 1)]
    pieces += [index[[i]] for i in np.flatnonzero(far)]
    return [pc for pc in pieces if pc.size]
