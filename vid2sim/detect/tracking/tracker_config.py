"""The tracker's thresholds (:class:`TrackerConfig`), apart from the tracker itself
(:mod:`vid2sim.detect.tracking.tracker`) so that settings can name them."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class TrackerConfig:
    """Tracker thresholds.

    :param high_score: detections at or above go to the first association stage
    :param low_score: detections below are ignored; between the two they go to stage two
    :param new_track_score: minimum score of an unmatched detection to start a track
    :param weak_start_score: an unmatched weaker detection (at least this score) starts a
        weak tentative track, which must then be found on ``weak_confirm_hits`` detected
        frames in a row (a small, far vehicle scores 0.2-0.45 frame after frame; a false
        detection of that score rarely repeats at the same place)
    :param weak_confirm_hits: detections in a row that confirm a weak tentative track
    :param weak_confirm_min_hits: fewer detections in a row also confirm it when they span
        ``weak_confirm_s`` or more (sparse input: a weak box repeated where the motion puts
        it 0.5 s later is the same evidence as four frames in a row of dense video), or when
        the input ends before a weak track found on every detected frame since its birth
        could reach ``weak_confirm_hits`` (a folder of three sparse keyframes)
    :param weak_confirm_s: the span that makes ``weak_confirm_min_hits`` enough [s]: 0.3 s,
        what ``weak_confirm_hits`` consecutive frames span at 10 fps, so dense 10 fps video
        is confirmed exactly as before
    :param iou_high: minimum IoU to match a confident detection (stage one)
    :param iou_low: minimum IoU to match a weak detection (stage two; stricter because weak
        boxes are noisier)
    :param iou_tentative: minimum IoU to match a not yet confirmed track
    :param weak_revive_s: a confirmed track lost for at most this long may be taken up again
        by a weak detection [s]: one missed frame (a far car scoring 0.13-0.26 frame after
        frame, once below the detector's floor) must not end it
    :param iou_weak_revive: minimum IoU of such a weak detection with the lost track's
        predicted box (stricter than ``iou_low``: the track was not seen on the last frame)
    :param max_lost_s: a track unmatched for longer than this is ended [s]
    :param min_hits: detections needed before a track is confirmed (in dense input; see
        ``sparse_interval_s``)
    :param sparse_interval_s: a tentative track is dropped when a detected frame less than
        this long after its birth misses it; after longer intervals it is kept [s]
    :param edge_noise_ratio: one-sigma error of a detected box edge as a fraction of the box
        height (localisation noise of the detector)
    :param lateral_speed_mps: one-sigma speed of a vehicle across the camera's line of sight
        not explained by the ego's forward motion (drift in lane, a slow lane change) [m/s]
    :param vehicle_height_m: typical vehicle height, converts lateral speed to box heights
        per second [m]
    :param growth_rate_per_s: one-sigma rate of growth of the log box size, i.e. closing
        speed over range (10 m/s at 10 m gives 1/s) [1/s]
    :param shrink_rate_per_s: the same for shrinking boxes: with the camera moving forward
        the static world grows, a box shrinks only behind a vehicle faster than the ego, and
        by little (3 m/s faster at 10 m gives 0.3/s) [1/s]
    :param border_margin_px: a box edge this close to the image border is taken as cut by it
        (detectors stop the box of a cut vehicle a few pixels short of the border)
    :param moving_penalty: extra chi-square cost of explaining a pair as a moving vehicle
        rather than a static one approached at the ego speed common to the frame (2 ln of
        the odds static : moving, 2 for odds of about 3 : 1)
    :param closing_time_constant_s: time constant of the filter on each track's closing
        rate (box growth) [s]
    :param max_static_rate_per_s: largest ego-motion hypothesis searched, as closing speed
        over range for a box ``static_rate_box_px`` high (30 m/s at 10 m: 3/s) [1/s]
    :param n_static_rates: ego-motion hypotheses searched from a standing ego up to
        ``max_static_rate_per_s`` (81: steps of 0.05/s, below the closing-rate noise of one
        frame pair)
    :param static_rate_box_px: box height the ego-motion hypotheses are stated for [px]
    """

    high_score: float = 0.45
    low_score: float = 0.1
    new_track_score: float = 0.5
    weak_start_score: float = 0.25
    weak_confirm_hits: int = 4
    weak_confirm_min_hits: int = 3
    weak_confirm_s: float = 0.3
    iou_high: float = 0.2
    iou_low: float = 0.4
    iou_tentative: float = 0.3
    weak_revive_s: float = 0.35
    iou_weak_revive: float = 0.5
    max_lost_s: float = 1.2
    min_hits: int = 2
    sparse_interval_s: float = 0.2
    edge_noise_ratio: float = 0.1
    lateral_speed_mps: float = 0.5
    vehicle_height_m: float = 1.5
    growth_rate_per_s: float = 1.0
    shrink_rate_per_s: float = 0.3
    border_margin_px: float = 8.0
    moving_penalty: float = 2.0
    closing_time_constant_s: float = 0.3
    max_static_rate_per_s: float = 4.0
    n_static_rates: int = 81
    static_rate_box_px: float = 100.0
