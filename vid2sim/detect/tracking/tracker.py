"""Multi-object tracking of vehicle boxes: a Kalman filter per track, ByteTrack-style association.

Association follows ByteTrack (Zhang et al., ECCV 2022): detections are split by score; the
confident ones are matched first to the live tracks (those seen on the last detected frame,
then the recently lost), then the weak ones (often partly occluded vehicles) to the tracks
still unmatched, so a vehicle fading behind another keeps its track instead of spawning
false ones. Matching is a min-cost assignment on 1 - IoU (Hungarian) with a gate.

Sparse input (a 2 frames/s video, ``--detect-every`` with long gaps, a track lost for a
while) breaks IoU: a car 8 m away beside a camera moving at 10 m/s doubles in size and
slides hundreds of pixels in 0.5 s, and a row of parked cars then looks like the same row
shifted by one car. Three additions handle it:

* an ego-motion association stage (:func:`vid2sim.detect.tracking.egomotion.expansion_cost`): a
  vehicle that is parked or drives parallel to the ego keeps its lateral offset and height,
  so its box scales about the focus of expansion (FOE) by the range ratio. The cost is a
  chi-square over the box edges: either "static", the ratio fixed by one ego closing rate
  shared by every vehicle in the frame (searched per frame) and the box height, or
  "moving", any ratio under a prior centred on the track's own measured closing rate, plus
  a penalty; a translation for lateral motion is allowed; priors grow with the elapsed
  time; border-cut edges only bound the fit. In sparse input (detected frames
  ``sparse_interval_s`` or more apart) it runs before the IoU stages, in dense video after
  them for what IoU left unmatched.
* tracks end when their own closing rate says the camera has passed them, so a car that
  left the view at the side is not revived by the next car to appear.
* confirmation that knows the detection rate: a tentative track is deleted as a false
  detection only when a detected frame less than ``sparse_interval_s`` after its birth fails
  to see it again (at 10 frames/s a real car is seen in the next frame; at 2 frames/s it may
  already have left the view). A track born in sparse input, or on the last detected frame
  of the video, that is never seen again is thus kept with its one confident box.

Assignments price an unmatched track or detection at half the gate: a pair is made only
when it beats leaving both alone, and pairs beyond the gate never steer the solution.

The Kalman state is (cx, cy, a, h, vcx, vcy, va, vh): box centre [px], aspect w/h, height
[px] and their rates per frame, with noise proportional to the box height (as in SORT and
ByteTrack), so a 20 px far car and a 200 px near car are filtered alike.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from vid2sim.core.boxes import (
    UNMATCHED_COST,
    border_cut,
    buffered_iou,
    match,
    xyxy_to_xyah,
)
from vid2sim.core.records import Detection, TrackedBox
from vid2sim.detect.tracking._box_kalman import BoxKalman
from vid2sim.detect.tracking.egomotion import PASSED_CLOSING, closing_rate, drift, expansion_cost
from vid2sim.detect.tracking.tracker_config import TrackerConfig

__all__ = ["LOST", "TRACKED", "Track", "Tracker", "TrackerConfig"]


# --------------------------------------------------------------------------- tracks

TRACKED = "tracked"
"""Track state: matched on the last detected frame."""
LOST = "lost"
"""Track state: missed on the last detected frame, still predicted (up to ``max_lost_s``)."""


@dataclass(slots=True)
class Track:
    """Everything the tracker knows about one track.

    :param track_id: id in order of creation (renumbered by :meth:`Tracker.finalize`)
    :param kf: Kalman filter of the box
    :param frame: frame the filter has been predicted to
    :param last_seen_t_s: time of the last matched detection [s]
    :param score: score of the last matched detection
    :param last_box_px: last matched detection box (x1, y1, x2, y2) [px]
    :param last_seen_frame: frame of the last matched detection
    :param born_t_s: time of the first detection [s]
    :param closing_rate_per_s: own approach speed over range, from box growth [1/s]
        (NaN until measured)
    :param drift_px_s: own image motion beyond expansion [px/s] (see
        :func:`~vid2sim.detect.tracking.egomotion.expansion_cost`)
    :param hits: detections matched so far (the first included)
    :param weak: started from a weak detection: needs ``weak_confirm_hits`` in a row
    :param confirmed: a vehicle, not a false detection (kept by :meth:`Tracker.finalize`)
    :param state: ``TRACKED`` or ``LOST``
    :param votes: summed score per category
    :param shown_box_px: box reported on the last frame [px] (detected, measured or
        predicted)
    """

    track_id: int
    kf: BoxKalman
    frame: int
    last_seen_t_s: float
    score: float
    last_box_px: np.ndarray
    last_seen_frame: int
    born_t_s: float
    closing_rate_per_s: float = float("nan")
    drift_px_s: np.ndarray = field(default_factory=lambda: np.zeros(2))
    hits: int = 1
    weak: bool = False
    confirmed: bool = False
    state: str = TRACKED
    votes: dict[str, float] = field(default_factory=lambda: defaultdict(float))
    shown_box_px: np.ndarray | None = None

    @property
    def category(self) -> str:
        """Score-weighted majority category so far."""
        return max(self.votes.items(), key=lambda kv: (kv[1], kv[0]))[0]

    def row(self, frame: int, t_s: float, box: np.ndarray, score: float) -> TrackedBox:
        """The output row of this track on ``frame``."""
        x1, y1, x2, y2 = (float(v) for v in box)
        return TrackedBox(frame=frame, t_s=float(t_s), track_id=self.track_id,
                          category=self.category, score=float(score),
                          x1=x1, y1=y1, x2=x2, y2=y2)


@dataclass(slots=True)
class _Step:
    """One detected frame being associated: what has been matched so far."""

    frame: int
    t_s: float
    rows: list[TrackedBox] = field(default_factory=list)
    matched: set[int] = field(default_factory=set)  # track ids

    def free(self, tracks: list[Track]) -> list[Track]:
        return [t for t in tracks if t.track_id not in self.matched]


class Tracker:
    """Online multi-vehicle tracker.

    Call :meth:`update` once per frame in order; it returns the boxes of the tracks alive in
    that frame. Tracks start tentative and are confirmed after ``min_hits`` detections. A
    tentative track missed by a detected frame is deleted (a false detection) when that
    frame came less than ``sparse_interval_s`` after the track's birth, else confirmed (a
    vehicle seen once in sparse input, which may have left the view since). :meth:`finalize`
    drops the never-confirmed tracks from the collected rows, except those born on the last
    detected frame (they had no chance of a second look), and fixes each track's category to
    its score-weighted majority vote.

    Parameters
    ----------
    config : TrackerConfig, optional
        Thresholds.
    image_size_px : (int, int), optional
        Frame width and height [px]: the focus of expansion is taken at the image centre and
        box edges on the border are recognised as cut. Without it each box scales about its
        own centre in the ego-motion stage.
    """

    def __init__(self, config: TrackerConfig | None = None,
                 image_size_px: tuple[int, int] | None = None):
        self.config = config or TrackerConfig()
        self.image_size_px = image_size_px
        self.foe_px = (None if image_size_px is None
                       else (image_size_px[0] / 2.0, image_size_px[1] / 2.0))
        self._tracks: list[Track] = []  # alive (tracked or lost)
        self._all: dict[int, Track] = {}  # every track ever started, by id (for finalize)
        self._next_id = 1
        self._last_detect_t_s: float | None = None
        self._last_measured_t_s: float | None = None  # detected, or carried by optical flow

    # ----------------------------------------------------------------- public

    def update(self, frame: int, t_s: float, detections: list[Detection] | None,
               measured: dict[int, np.ndarray] | None = None,
               seen: Callable[[np.ndarray], np.ndarray] | None = None) -> list[TrackedBox]:
        """Advance to ``frame`` (time ``t_s`` [s]) and return the boxes alive there.

        Parameters
        ----------
        frame : int
            Frame index; must increase from call to call.
        t_s : float
            Frame time [s], used for the lost-track timeout and the ego-motion gate.
        detections : list of Detection or None
            Boxes found in this frame, or None when the detector did not run on it: tracks
            are then carried with their last score.
        measured : dict, optional
            On a frame without detections: boxes of tracks measured another way (track id ->
            (x1, y1, x2, y2) [px], e.g. carried by optical flow, see
            :mod:`vid2sim.detect.tracking.flow`). They correct the track's filter and are its row;
            they neither confirm a track nor count as a detection. On a frame with
            detections, the boxes of the tracks the detector did not look at (``seen``).
        seen : callable, optional
            For a detector run that looked at part of the frame only: which of the boxes
            given (n, 4) [px], the tracks' predicted boxes, it looked at well enough to have
            found a vehicle there. A track no detection took is missed (lost, or deleted if
            tentative) only there; elsewhere it is carried as on a frame without detections
            (its ``measured`` box, else its prediction), neither missed nor seen. None: the
            detector looked at the whole frame.

        Returns
        -------
        list of TrackedBox
            One row per tracked (not lost) track: the detection box on a matched frame, the
            measured or else the predicted box on a carried frame.
        """
        self._predict(frame)
        if detections is None:
            return self._carry(frame, t_s, measured or {})
        cfg = self.config
        # Sparse input: boxes move too far between measured frames for IoU to come first.
        sparse = (self._last_measured_t_s is not None
                  and t_s - self._last_measured_t_s >= cfg.sparse_interval_s)
        self._last_detect_t_s = self._last_measured_t_s = t_s
        dets = [d for d in detections if d.score >= cfg.low_score]
        high = [d for d in dets if d.score >= cfg.high_score]
        low = [d for d in dets if d.score < cfg.high_score]
        step = _Step(frame, t_s)
        self._drop_passed(t_s)
        # Dense video: IoU on the Kalman prediction first, the motion model for what is left.
        # Sparse input: the motion model first (IoU would join a row of parked cars shifted
        # by one car), IoU on the prediction for what is left (e.g. crossing traffic).
        stages = ((self._motion_stage, self._iou_stages) if sparse
                  else (self._iou_stages, self._motion_stage))
        for stage in stages:
            high, low = stage(step, high, low)
        dead = self._handle_misses(step, seen, measured or {})
        self._start_tracks(step, high, low)
        self._tracks = [t for t in self._tracks if t.track_id not in dead
                        and t_s - t.last_seen_t_s <= cfg.max_lost_s]
        step.rows.sort(key=lambda r: r.track_id)
        return step.rows

    def finalize(self, rows: list[TrackedBox]) -> list[TrackedBox]:
        """Clean the rows collected from :meth:`update` over a whole video.

        Drops rows of tracks never confirmed, except tracks born on the last detected frame
        (seen once with a confident score and never given a second look) and weak tracks
        found on every detected frame since their birth, ``weak_confirm_min_hits`` times or
        more, when the input ended (they had no chance to reach ``weak_confirm_hits``), sets
        every row's
        category to its track's score-weighted majority vote, and renumbers track ids 1, 2,
        ... in order of first appearance.
        """
        cfg = self.config
        keep = {tid for tid, t in self._all.items() if t.confirmed}
        keep |= {t.track_id for t in self._tracks
                 if t.born_t_s == self._last_detect_t_s and not t.weak}
        # A weak tentative track still alive was found on every detected frame since its
        # birth: the input ended before it could reach weak_confirm_hits (a folder of three
        # sparse keyframes, a clip's last frames); weak_confirm_min_hits in a row suffice.
        keep |= {t.track_id for t in self._tracks
                 if t.weak and not t.confirmed and t.hits >= cfg.weak_confirm_min_hits}
        new_id: dict[int, int] = {}
        out = []
        for r in sorted(rows, key=lambda r: (r.frame, r.track_id)):
            if r.track_id not in keep:
                continue
            if r.track_id not in new_id:
                new_id[r.track_id] = len(new_id) + 1
            out.append(TrackedBox(frame=r.frame, t_s=r.t_s, track_id=new_id[r.track_id],
                                  category=self._all[r.track_id].category, score=r.score,
                                  x1=r.x1, y1=r.y1, x2=r.x2, y2=r.y2))
        return out

    def shown_boxes(self) -> tuple[list[int], np.ndarray]:
        """Ids and boxes (n, 4) [px] of the tracks reported on the last frame (tracked, not
        lost): what optical flow carries into the next frame."""
        shown = [t for t in self._tracks if t.state == TRACKED]
        boxes = np.array([t.shown_box_px for t in shown], dtype=float).reshape(-1, 4)
        return [t.track_id for t in shown], boxes

    def tracks(self) -> list[Track]:
        return list(self._tracks)  # alive (tracked or lost), for schedules to look at

    # ----------------------------------------------------------------- the steps of update

    def _carry(self, frame: int, t_s: float, measured: dict[int, np.ndarray],
               tracks: list[Track] | None = None) -> list[TrackedBox]:
        """Rows of a frame without detections (or of ``tracks``, which the detector did not
        look at): measured boxes correct their filters."""
        rows = []
        for t in (self._tracks if tracks is None else tracks):
            if t.state != TRACKED:
                continue
            box = measured.get(t.track_id)
            if box is not None:
                box = np.asarray(box, dtype=float)
                t.kf.update(box)
            box = t.kf.box_px if box is None else box
            t.shown_box_px = box
            rows.append(t.row(frame, t_s, box, t.score))
        if measured and tracks is None:
            self._last_measured_t_s = t_s
        return rows

    def _predict(self, frame: int) -> None:
        for track in self._tracks:  # every alive track's filter predicted to ``frame``
            track.kf.predict(frame - track.frame)
            track.frame = frame

    def _drop_passed(self, t_s: float) -> None:
        """End lost tracks whose own approach has since carried them past the camera (range
        down to a tenth) or that left the view at the side: no box may revive them."""
        self._tracks = [t for t in self._tracks if not (
            t.state == LOST
            and (t.closing_rate_per_s * (t_s - t.last_seen_t_s) >= PASSED_CLOSING
                 or self._left_through_side(t)))]

    def _iou_stages(self, step: _Step, high: list[Detection], low: list[Detection]
                    ) -> tuple[list[Detection], list[Detection]]:
        """ByteTrack's IoU stages on the Kalman prediction; returns the detections left."""
        cfg = self.config
        free = step.free(self._tracks)
        confirmed = [t for t in free if t.confirmed]
        tentative = [t for t in free if not t.confirmed]
        # Stage 1: confident detections, tracks seen on the last detected frame before the
        # lost (DeepSORT's cascade): a lost car's wide prediction took the lead that hid it.
        free_tracks: list[int] = []
        free_high = list(range(len(high)))
        for state in (TRACKED, LOST):
            idx = [i for i, t in enumerate(confirmed) if t.state == state]
            dets = [high[i] for i in free_high]
            pairs, free_t, free_d = self._associate([confirmed[i] for i in idx], dets,
                                                    cfg.iou_high)
            for ti, di in pairs:
                self._hit(step, confirmed[idx[ti]], dets[di])
            free_tracks += [idx[i] for i in free_t]
            free_high = [free_high[i] for i in free_d]
        # Stage 2: weak detections against tracks seen on the previous detected frame;
        # a weak box revives a lost track only after a short gap and on a close overlap.
        remaining = [confirmed[i] for i in free_tracks if confirmed[i].state == TRACKED]
        pairs, _, free_low = self._associate(remaining, low, cfg.iou_low)
        for ti, di in pairs:
            self._hit(step, remaining[ti], low[di])
        brief = [confirmed[i] for i in free_tracks if confirmed[i].state == LOST
                 and step.t_s - confirmed[i].last_seen_t_s <= cfg.weak_revive_s]
        if brief and free_low:
            left = [low[i] for i in free_low]
            pairs, _, free_left = self._associate(brief, left, cfg.iou_weak_revive)
            for ti, di in pairs:
                self._hit(step, brief[ti], left[di])
            free_low = [free_low[i] for i in free_left]
        # Stage 3: tentative tracks get one chance with the leftover confident detections.
        left_high = [high[i] for i in free_high]
        pairs, free_tent, free_new = self._associate(tentative, left_high, cfg.iou_tentative)
        for ti, di in pairs:
            self._hit(step, tentative[ti], left_high[di])
        # Stage 4: weak tentative tracks also with the leftover weak detections.
        weak_tracks = [tentative[i] for i in free_tent if tentative[i].weak]
        left_low = [low[i] for i in free_low]
        usable = [i for i, d in enumerate(left_low) if d.score >= cfg.weak_start_score]
        pairs, _, _ = self._associate(weak_tracks, [left_low[i] for i in usable],
                                      cfg.iou_tentative)
        for ti, di in pairs:
            self._hit(step, weak_tracks[ti], left_low[usable[di]])
        used = {usable[di] for _, di in pairs}
        return ([left_high[i] for i in free_new],
                [d for i, d in enumerate(left_low) if i not in used])

    def _motion_stage(self, step: _Step, high: list[Detection], low: list[Detection]
                      ) -> tuple[list[Detection], list[Detection]]:
        """The ego-motion model (large image motion between sparse detections, or after a
        gap); weak boxes again only for confirmed tracks seen on the previous frame. Weak
        tentative tracks only by IoU (stages 3-4): the motion model's wide gates would let
        them take boxes from the confirmed tracks they lie near."""
        unmatched = [t for t in step.free(self._tracks) if not (t.weak and not t.confirmed)]
        pairs, _, free_high, rate = self._associate_motion(unmatched, high, step.t_s)
        for ti, di in pairs:
            self._hit(step, unmatched[ti], high[di], restart=True)
        unmatched = [t for t in step.free(unmatched) if t.state == TRACKED and t.confirmed]
        pairs, _, free_low, _ = self._associate_motion(unmatched, low, step.t_s, rate)
        for ti, di in pairs:
            self._hit(step, unmatched[ti], low[di], restart=True)
        return [high[i] for i in free_high], [low[i] for i in free_low]

    def _handle_misses(self, step: _Step, seen: Callable[[np.ndarray], np.ndarray] | None,
                       measured: dict[int, np.ndarray]) -> set[int]:
        """Tracks missed by this detected frame: a confirmed track goes lost; a tentative one
        is a false detection (returned, to be deleted) if the vehicle, were it real, should
        have been seen again by now, else it is confirmed and goes lost. Tracks where the
        detector did not look (``seen``) are not missed: they are carried (their rows added
        to the step's)."""
        dead: set[int] = set()
        free = step.free(self._tracks)
        if seen is not None and free:
            looked = np.asarray(seen(np.array([t.kf.box_px for t in free])), dtype=bool)
            carried = [t for t, ok in zip(free, looked, strict=True) if not ok]
            step.rows.extend(self._carry(step.frame, step.t_s, measured, carried))
            free = [t for t, ok in zip(free, looked, strict=True) if ok]
        for track in free:
            if track.confirmed:
                track.state = LOST
            elif track.weak or step.t_s - track.born_t_s < self.config.sparse_interval_s:
                dead.add(track.track_id)
            else:
                track.confirmed = True
                track.state = LOST
        return dead

    def _start_tracks(self, step: _Step, high: list[Detection], low: list[Detection]) -> None:
        """New tracks from the detections no track took: confident ones start ordinary
        tracks, weaker ones (down to ``weak_start_score``) weak tentative tracks."""
        cfg = self.config
        for det in high:
            if det.score >= cfg.new_track_score:
                track = self._start(det, step.frame, step.t_s)
                step.rows.append(track.row(step.frame, step.t_s, np.asarray(det.box_px),
                                           det.score))
        for det in low + [d for d in high if d.score < cfg.new_track_score]:
            if det.score >= cfg.weak_start_score:
                track = self._start(det, step.frame, step.t_s, weak=True)
                step.rows.append(track.row(step.frame, step.t_s, np.asarray(det.box_px),
                                           det.score))

    # ----------------------------------------------------------------- internals

    def _left_through_side(self, track: Track) -> bool:
        """A lost track last seen cut by the left or right border whose predicted centre
        has since moved out of the image: the vehicle left the view at the side (passed or
        turned away), and a box that appears later is another vehicle."""
        if self.image_size_px is None:
            return False
        cut = border_cut(track.last_box_px[None, :], self.image_size_px,
                         self.config.border_margin_px)[0]
        if not (cut[0] or cut[2]):
            return False
        box = track.kf.box_px
        centre = 0.5 * (box[0] + box[2])
        return bool(centre < 0 or centre > self.image_size_px[0])

    @staticmethod
    def _associate(tracks: list[Track], dets: list[Detection], min_iou: float):
        if not tracks or not dets:
            return [], list(range(len(tracks))), list(range(len(dets)))
        boxes = np.array([d.box_px for d in dets], dtype=float)
        iou = np.vstack([buffered_iou(t.kf.box_px, t.kf.position_std_px(), boxes)
                         for t in tracks])
        return match(1.0 - iou, 1.0 - min_iou)

    def _associate_motion(self, tracks: list[Track], dets: list[Detection], t_s: float,
                          rate_per_px_s: float | None = None):
        """Match on :func:`expansion_cost`, searching the ego-motion rate shared by all
        static vehicles (or using ``rate_per_px_s``): the rate whose assignment costs least,
        counting each pair left unmatched at the gate's cost of 1, wins.

        Returns pairs, unmatched tracks, unmatched detections and the rate used.
        """
        if not tracks or not dets:
            return [], list(range(len(tracks))), list(range(len(dets))), rate_per_px_s
        cfg = self.config
        if rate_per_px_s is None:
            rates = (np.linspace(0.0, cfg.max_static_rate_per_s, cfg.n_static_rates)
                     / cfg.static_rate_box_px)
        else:
            rates = np.array([rate_per_px_s])
        costs = expansion_cost(np.array([t.last_box_px for t in tracks]),
                               np.array([t_s - t.last_seen_t_s for t in tracks]),
                               np.array([d.box_px for d in dets], dtype=float),
                               foe_px=self.foe_px, image_size_px=self.image_size_px,
                               config=cfg, static_rates_per_px_s=rates,
                               closing_rate_per_s=np.array([t.closing_rate_per_s
                                                            for t in tracks]),
                               drift_px_s=np.array([t.drift_px_s for t in tracks]))
        n_pairs = min(len(tracks), len(dets))
        best = None
        for rate, cost in zip(rates, costs, strict=True):
            # costs are normalised by their gate: 1 is the gate itself
            found = match(np.where(np.isfinite(cost), cost, UNMATCHED_COST), 1.0)
            total = sum(cost[r, c] for r, c in found[0]) + (n_pairs - len(found[0]))
            if best is None or total < best[0] - 1e-9:
                best = (total, found, float(rate))
        pairs, free_tracks, free_dets = best[1]
        return pairs, free_tracks, free_dets, best[2]

    def _start(self, det: Detection, frame: int, t_s: float, weak: bool = False) -> Track:
        box = np.asarray(det.box_px, dtype=float)
        track = Track(track_id=self._next_id, kf=BoxKalman(box), frame=frame,
                      last_seen_t_s=t_s, score=det.score, last_box_px=box,
                      last_seen_frame=frame, born_t_s=t_s, weak=weak, shown_box_px=box)
        track.votes[det.category] += det.score
        track.confirmed = self.config.min_hits <= 1 and not weak
        self._next_id += 1
        self._all[track.track_id] = track
        self._tracks.append(track)
        return track

    def _hit(self, step: _Step, track: Track, det: Detection, restart: bool = False) -> None:
        """Continue ``track`` with ``det`` on this step's frame and add its row."""
        frame, t_s = step.frame, step.t_s
        box = np.asarray(det.box_px, dtype=float)
        if restart:
            # joined by the ego-motion stage, typically far from the constant-velocity
            # prediction: restart the filter at the new box with the velocity of the jump
            # rather than let a stale state pull the estimate back
            dt_frames = max(frame - track.last_seen_frame, 1)
            velocity = (xyxy_to_xyah(box) - xyxy_to_xyah(track.last_box_px)) / dt_frames
            track.kf = BoxKalman(box)
            track.kf.mean[4:] = velocity
            track.kf.mean[6] = 0.0
        else:
            track.kf.update(box)
        cfg = self.config
        dt_s = t_s - track.last_seen_t_s
        # first-order filters: box noise over 0.1 s makes single measurements jumpy
        alpha = dt_s / (dt_s + cfg.closing_time_constant_s) if dt_s > 0 else 0.0
        measured = closing_rate(track.last_box_px, box, dt_s, self.image_size_px,
                                cfg.border_margin_px)
        if np.isfinite(measured):
            previous = track.closing_rate_per_s
            track.closing_rate_per_s = (measured if not np.isfinite(previous)
                                        else previous + alpha * (measured - previous))
        moved = drift(track.last_box_px, box, dt_s, self.foe_px, self.image_size_px,
                      cfg.border_margin_px)
        if moved is not None:
            track.drift_px_s = moved if track.hits == 1 else track.drift_px_s + alpha * (
                moved - track.drift_px_s)
        track.state = TRACKED
        track.last_seen_t_s = t_s
        track.last_box_px = track.shown_box_px = box
        track.last_seen_frame = frame
        track.score = det.score
        track.votes[det.category] += det.score
        track.hits += 1
        if track.weak:
            # "in a row": a weak tentative track missed once is deleted (_handle_misses)
            track.confirmed |= (track.hits >= cfg.weak_confirm_hits
                                or (track.hits >= cfg.weak_confirm_min_hits
                                    and t_s - track.born_t_s >= cfg.weak_confirm_s - 1e-6))
        elif track.hits >= cfg.min_hits:
            track.confirmed = True
        step.rows.append(track.row(frame, t_s, box, det.score))
        step.matched.add(track.track_id)
