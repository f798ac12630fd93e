"""Multi-object tracking of vehicle boxes: a Kalman filter per track, ByteTrack-style association.

Association follows ByteTrack (Zhang et al., ECCV 2022): detections are split by score; the
confident ones are matched first to every live track (tracked or recently lost), then the
weak ones (which are often partly occluded vehicles) are matched to the tracks still
unmatched, so a vehicle fading behind another keeps its track instead of spawning false
ones. Matching is a min-cost assignment on 1 - IoU (scipy's Hungarian solver) with a gate.

The Kalman state is (cx, cy, a, h, vcx, vcy, va, vh): box centre [px], aspect w/h, height
[px] and their rates per frame, with noise proportional to the box height (as in SORT and
ByteTrack), so a 20 px far car and a 200 px near car are filtered alike.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from vid2sim.records import Detection, TrackedBox


@dataclass(frozen=True, slots=True)
class TrackerConfig:
    """Tracker thresholds.

    :param high_score: detections at or above go to the first association stage
    :param low_score: detections below are ignored; between the two they go to stage two
    :param new_track_score: minimum score of an unmatched detection to start a track
    :param iou_high: minimum IoU to match a confident detection (stage one)
    :param iou_low: minimum IoU to match a weak detection (stage two; stricter because weak
        boxes are noisier)
    :param iou_tentative: minimum IoU to match a not yet confirmed track
    :param max_lost_s: a track unmatched for longer than this is ended [s]
    :param min_hits: detections needed before a track is confirmed
    """

    high_score: float = 0.45
    low_score: float = 0.1
    new_track_score: float = 0.5
    iou_high: float = 0.2
    iou_low: float = 0.4
    iou_tentative: float = 0.3
    max_lost_s: float = 1.2
    min_hits: int = 2


# --------------------------------------------------------------------------- geometry


def iou_matrix(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """Pairwise IoU of two sets of (x1, y1, x2, y2) boxes, shape (len(a), len(b))."""
    a = np.asarray(boxes_a, dtype=float).reshape(-1, 4)
    b = np.asarray(boxes_b, dtype=float).reshape(-1, 4)
    ix1 = np.maximum(a[:, None, 0], b[None, :, 0])
    iy1 = np.maximum(a[:, None, 1], b[None, :, 1])
    ix2 = np.minimum(a[:, None, 2], b[None, :, 2])
    iy2 = np.minimum(a[:, None, 3], b[None, :, 3])
    inter = np.clip(ix2 - ix1, 0, None) * np.clip(iy2 - iy1, 0, None)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)


def xyxy_to_xyah(box: np.ndarray) -> np.ndarray:
    """(x1, y1, x2, y2) -> (cx, cy, w/h, h)."""
    x1, y1, x2, y2 = box
    h = max(y2 - y1, 1e-6)
    return np.array([(x1 + x2) / 2, (y1 + y2) / 2, (x2 - x1) / h, h])


def xyah_to_xyxy(state: np.ndarray) -> np.ndarray:
    """(cx, cy, w/h, h, ...) -> (x1, y1, x2, y2)."""
    cx, cy, a, h = state[:4]
    w = a * h
    return np.array([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2])


def buffered_iou(box_px: np.ndarray, std_px: tuple[float, float], boxes_px: np.ndarray,
                 n_sigma: float = 2.0) -> np.ndarray:
    """IoU of one predicted box with many boxes, all grown by the prediction's uncertainty.

    Both sides are widened by ``n_sigma`` standard deviations of the predicted centre in x
    and y (the "buffered IoU" idea of C-BIoU, Yang et al. WACV 2023, with the buffer taken
    from the Kalman covariance instead of a fixed ratio). A track predicted over several
    frames (``--detect-every N``, a short occlusion, a new track with unknown velocity) thus
    still overlaps the car's new box, while a well-tracked box keeps a tight gate.
    """
    bx, by = n_sigma * std_px[0], n_sigma * std_px[1]
    grow = np.array([-bx, -by, bx, by])
    return iou_matrix((np.asarray(box_px, float) + grow)[None], np.asarray(boxes_px) + grow)[0]


def match(cost: np.ndarray, max_cost: float) -> tuple[list[tuple[int, int]], list[int], list[int]]:
    """Min-cost one-to-one assignment, rejecting pairs costlier than ``max_cost``.

    Returns matched (row, col) pairs, unmatched rows, unmatched columns.
    """
    n_rows, n_cols = cost.shape
    if n_rows == 0 or n_cols == 0:
        return [], list(range(n_rows)), list(range(n_cols))
    rows, cols = linear_sum_assignment(cost)
    pairs = [(int(r), int(c)) for r, c in zip(rows, cols, strict=True) if cost[r, c] <= max_cost]
    used_r = {r for r, _ in pairs}
    used_c = {c for _, c in pairs}
    return (pairs, [r for r in range(n_rows) if r not in used_r],
            [c for c in range(n_cols) if c not in used_c])


# --------------------------------------------------------------------------- Kalman filter


class BoxKalman:
    """Constant-velocity Kalman filter on (cx, cy, a, h); time step in frames.

    Noise standard deviations are fractions of the box height per frame: 1/20 for position,
    1/160 for velocity (the values SORT/DeepSORT/ByteTrack use), a fixed small value for the
    aspect ratio, which changes slowly.
    """

    STD_POSITION = 1.0 / 20.0
    STD_VELOCITY = 1.0 / 160.0

    def __init__(self, box_px: np.ndarray):
        z = xyxy_to_xyah(box_px)
        self.mean = np.concatenate([z, np.zeros(4)])
        h = z[3]
        std = np.array([2 * self.STD_POSITION * h, 2 * self.STD_POSITION * h, 1e-2,
                        2 * self.STD_POSITION * h, 10 * self.STD_VELOCITY * h,
                        10 * self.STD_VELOCITY * h, 1e-5, 10 * self.STD_VELOCITY * h])
        self.cov = np.diag(std ** 2)

    def predict(self, dt_frames: float) -> None:
        """Propagate by ``dt_frames`` frames (may be fractional or several)."""
        if dt_frames <= 0:
            return
        f = np.eye(8)
        f[:4, 4:] = np.eye(4) * dt_frames
        h = max(self.mean[3], 1.0)
        std_q = np.array([self.STD_POSITION * h, self.STD_POSITION * h, 1e-2,
                          self.STD_POSITION * h, self.STD_VELOCITY * h, self.STD_VELOCITY * h,
                          1e-5, self.STD_VELOCITY * h])
        self.mean = f @ self.mean
        # random-walk noise grows linearly with the elapsed frames
        self.cov = f @ self.cov @ f.T + np.diag(std_q ** 2) * dt_frames
        self.mean[3] = max(self.mean[3], 1.0)
        self.mean[2] = max(self.mean[2], 1e-3)

    def update(self, box_px: np.ndarray) -> None:
        """Correct with a measured box (x1, y1, x2, y2) [px]."""
        z = xyxy_to_xyah(box_px)
        h = max(self.mean[3], 1.0)
        r = np.diag(np.array([self.STD_POSITION * h, self.STD_POSITION * h, 1e-1,
                              self.STD_POSITION * h]) ** 2)
        hm = np.zeros((4, 8))
        hm[:, :4] = np.eye(4)
        s = hm @ self.cov @ hm.T + r
        k = np.linalg.solve(s, hm @ self.cov).T
        self.mean = self.mean + k @ (z - hm @ self.mean)
        self.cov = (np.eye(8) - k @ hm) @ self.cov

    @property
    def box_px(self) -> np.ndarray:
        """Current box estimate (x1, y1, x2, y2) [px]."""
        return xyah_to_xyxy(self.mean)

    def position_std_px(self) -> tuple[float, float]:
        """One-sigma uncertainty of the box centre (x, y) [px]."""
        return float(np.sqrt(self.cov[0, 0])), float(np.sqrt(self.cov[1, 1]))


# --------------------------------------------------------------------------- tracks


@dataclass(slots=True)
class _Track:
    track_id: int
    kf: BoxKalman
    frame: int
    last_seen_t_s: float
    score: float
    hits: int = 1
    state: str = "tracked"  # "tracked" (matched last detected frame) or "lost"
    votes: dict[str, float] = field(default_factory=lambda: defaultdict(float))

    @property
    def category(self) -> str:
        return max(self.votes.items(), key=lambda kv: (kv[1], kv[0]))[0]


class Tracker:
    """Online multi-vehicle tracker.

    Call :meth:`update` once per frame in order; it returns the boxes of the tracks alive in
    that frame. Tracks start tentative and are confirmed after ``min_hits`` detections;
    :meth:`finalize` drops the never-confirmed ones (mostly false detections) from the
    collected rows and fixes each track's category to its score-weighted majority vote.

    Parameters
    ----------
    config : TrackerConfig, optional
        Thresholds.
    """

    def __init__(self, config: TrackerConfig | None = None):
        self.config = config or TrackerConfig()
        self._tracks: list[_Track] = []
        self._next_id = 1
        self._hits: dict[int, int] = {}
        self._votes: dict[int, dict[str, float]] = {}

    # ----------------------------------------------------------------- public

    def update(self, frame: int, t_s: float, detections: list[Detection] | None
               ) -> list[TrackedBox]:
        """Advance to ``frame`` (time ``t_s`` [s]) and return the boxes alive there.

        Parameters
        ----------
        frame : int
            Frame index; must increase from call to call.
        t_s : float
            Frame time [s], used for the lost-track timeout.
        detections : list of Detection or None
            Boxes found in this frame, or None when the detector did not run on it: tracks
            are then only predicted and carried with their last score.

        Returns
        -------
        list of TrackedBox
            One row per tracked (not lost) track: the detection box on a matched frame, the
            predicted box on a carried frame.
        """
        for track in self._tracks:
            track.kf.predict(frame - track.frame)
            track.frame = frame
        if detections is None:
            return [self._row(t, frame, t_s, t.kf.box_px, t.score)
                    for t in self._tracks if t.state == "tracked"]

        cfg = self.config
        dets = [d for d in detections if d.score >= cfg.low_score]
        high = [d for d in dets if d.score >= cfg.high_score]
        low = [d for d in dets if d.score < cfg.high_score]
        rows: list[TrackedBox] = []

        confirmed = [t for t in self._tracks if self._hits[t.track_id] >= cfg.min_hits]
        tentative = [t for t in self._tracks if self._hits[t.track_id] < cfg.min_hits]

        # Stage 1: confident detections against all confirmed tracks, tracked or lost.
        pairs, free_tracks, free_high = self._associate(confirmed, high, cfg.iou_high)
        for ti, di in pairs:
            rows.append(self._hit(confirmed[ti], high[di], frame, t_s))
        # Stage 2: weak detections only against tracks seen on the previous detected frame;
        # a weak box is not trusted to revive a lost track.
        remaining = [confirmed[i] for i in free_tracks if confirmed[i].state == "tracked"]
        pairs, free2, _ = self._associate(remaining, low, cfg.iou_low)
        for ti, di in pairs:
            rows.append(self._hit(remaining[ti], low[di], frame, t_s))
        for i in free2:
            remaining[i].state = "lost"
        # Stage 3: tentative tracks get one chance with the leftover confident detections.
        left_high = [high[i] for i in free_high]
        pairs, free_t, free_new = self._associate(tentative, left_high, cfg.iou_tentative)
        for ti, di in pairs:
            rows.append(self._hit(tentative[ti], left_high[di], frame, t_s))
        dead = {id(tentative[i]) for i in free_t}
        # New tracks from confident leftovers.
        for i in free_new:
            det = left_high[i]
            if det.score >= cfg.new_track_score:
                track = self._start(det, frame, t_s)
                rows.append(self._row(track, frame, t_s, np.asarray(det.box_px), det.score))
        self._tracks = [t for t in self._tracks if id(t) not in dead
                        and t_s - t.last_seen_t_s <= cfg.max_lost_s]
        rows.sort(key=lambda r: r.track_id)
        return rows

    def finalize(self, rows: list[TrackedBox]) -> list[TrackedBox]:
        """Clean the rows collected from :meth:`update` over a whole video.

        Drops rows of tracks never confirmed, sets every row's category to its track's
        score-weighted majority vote, and renumbers track ids 1, 2, ... in order of first
        appearance.
        """
        keep = {tid for tid, n in self._hits.items() if n >= self.config.min_hits}
        new_id: dict[int, int] = {}
        out = []
        for r in sorted(rows, key=lambda r: (r.frame, r.track_id)):
            if r.track_id not in keep:
                continue
            if r.track_id not in new_id:
                new_id[r.track_id] = len(new_id) + 1
            votes = self._votes[r.track_id]
            category = max(votes.items(), key=lambda kv: (kv[1], kv[0]))[0]
            out.append(TrackedBox(frame=r.frame, t_s=r.t_s, track_id=new_id[r.track_id],
                                  category=category, score=r.score, x1=r.x1, y1=r.y1,
                                  x2=r.x2, y2=r.y2))
        return out

    # ----------------------------------------------------------------- internals

    @staticmethod
    def _associate(tracks: list[_Track], dets: list[Detection], min_iou: float):
        if not tracks or not dets:
            return [], list(range(len(tracks))), list(range(len(dets)))
        boxes = np.array([d.box_px for d in dets], dtype=float)
        iou = np.vstack([buffered_iou(t.kf.box_px, t.kf.position_std_px(), boxes)
                         for t in tracks])
        return match(1.0 - iou, 1.0 - min_iou)

    def _start(self, det: Detection, frame: int, t_s: float) -> _Track:
        track = _Track(track_id=self._next_id, kf=BoxKalman(np.asarray(det.box_px)),
                       frame=frame, last_seen_t_s=t_s, score=det.score)
        track.votes[det.category] += det.score
        self._next_id += 1
        self._hits[track.track_id] = 1
        self._votes[track.track_id] = track.votes
        self._tracks.append(track)
        return track

    def _hit(self, track: _Track, det: Detection, frame: int, t_s: float) -> TrackedBox:
        box = np.asarray(det.box_px, dtype=float)
        track.kf.update(box)
        track.state = "tracked"
        track.last_seen_t_s = t_s
        track.score = det.score
        track.votes[det.category] += det.score
        self._hits[track.track_id] += 1
        return self._row(track, frame, t_s, box, det.score)

    @staticmethod
    def _row(track: _Track, frame: int, t_s: float, box: np.ndarray, score: float
             ) -> TrackedBox:
        x1, y1, x2, y2 = (float(v) for v in box)
        return TrackedBox(frame=frame, t_s=float(t_s), track_id=track.track_id,
                          category=track.category, score=float(score),
                          x1=x1, y1=y1, x2=x2, y2=y2)
