"""The settings of the replay videos (``vid2sim render``, ``build --render``,
``test-policy --render``): every tuned number of the drawing and the encoding, with its
reason. A light module (dataclasses only) so that :class:`vid2sim.app.settings.Settings` can
hold them without loading the renderer."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class BirdsEyeConfig:
    """How much of the scene the view shows and how its markings are drawn."""

    #: road shown ahead of the ego [m]: beyond the 50 m of the sampled frames' render, so a
    #: lead at the monocular ranging's useful reach (~60 m) is in the picture
    ahead_m: float = 60.0
    #: road shown behind the ego [m]: a follower at a 1 s gap at 50 km/h
    behind_m: float = 15.0
    #: broken lane line: 3 m of paint in every 9 m (Germany's urban "Leitlinie", RMS 2 /
    #: StVO; the UK and US urban patterns are 3 m in 9 m / 10 ft in 40 ft alike)
    dash_on_m: float = 3.0
    dash_period_m: float = 9.0
    #: spacing at which centerlines are resampled before they are offset to lane edges [m]
    sample_m: float = 1.0
    #: the scale bar is the largest of 1-2-5 x 10^k metres within this share of the width
    scale_bar_share: float = 0.3


@dataclass(frozen=True, slots=True)
class OverlayConfig:
    """How the scenario's vehicles are judged and how far its lane is drawn."""

    #: IoU at which a projected vehicle counts as on its box: KITTI's threshold for cars
    #: (Geiger et al., CVPR 2012)
    iou_good: float = 0.7
    #: IoU at which it counts as roughly there: PASCAL VOC's detection threshold
    #: (Everingham et al., IJCV 2010)
    iou_fair: float = 0.5
    #: the lane's edges are drawn from this far ahead [m] (the bonnet hides nearer road)
    lane_near_m: float = 3.0
    #: to this far ahead [m]: beyond ~40 m a lane edge is a few pixels wide
    lane_far_m: float = 40.0


@dataclass(frozen=True, slots=True)
class StripConfig:
    """Thresholds of the TTC band and how long an event's caption stays."""

    #: TTC below which the band is red [s]: the line summary.html draws as critical (Euro NCAP
    #: AEB tests brake at TTC 1-1.5 s)
    ttc_critical_s: float = 1.5
    #: TTC below which it is yellow [s]: forward-collision warnings sound at 2-3 s (NHTSA's FCW
    #: confirmation test expects a warning by 2.1-2.4 s)
    ttc_warn_s: float = 3.0
    #: an event's caption stays this long after the event [s]: long enough to read it at
    #: playback speed
    event_show_s: float = 2.0


@dataclass(frozen=True, slots=True)
class EncoderConfig:
    """How the replay is encoded."""

    #: x264's constant rate factor: its default, visually near-lossless for drawn overlays
    #: at a tenth of the size of ``mp4v`` at OpenCV's default quality
    crf: int = 23
    #: x264's speed preset: "veryfast" encodes a KITTI-sized replay frame (2 Mpx) in a few
    #: ms of CPU with files ~10% larger than "medium" (benchmarks/bench_render.py)
    preset: str = "veryfast"
    #: encoder threads: the shared two-core machine's cores (x264's own default is 1.5x the
    #: cores)
    threads: int = 2


@dataclass(frozen=True, slots=True)
class ReplayVideoConfig:
    """The replay video's layout and its parts' settings."""

    birdseye: BirdsEyeConfig = field(default_factory=BirdsEyeConfig)
    overlay: OverlayConfig = field(default_factory=OverlayConfig)
    strip: StripConfig = field(default_factory=StripConfig)
    encoder: EncoderConfig = field(default_factory=EncoderConfig)
    #: the strip's height as a share of the video's: room for a line of text and two plots
    #: of a few tens of pixels each at any size
    strip_share: float = 0.32
    #: and at least this many pixels (a 374 px KITTI frame gets 120)
    strip_min_px: int = 110
    #: the bird's-eye view is at least this share of the video's width: with it the picture
    #: is 1.5x the video's width, the camera kept at full resolution
    birdseye_share: float = 0.5
    #: and at least this share of its own height (wide enough to show both kerbs)
    birdseye_aspect: float = 0.75
    #: grey of the camera half without a video
    canvas_grey: int = 90
