"""Real footage seen through another, exactly known camera: crop, scale, turn and distort.

A rectified pinhole video (KITTI raw 0001, the TRI DGP front camera) is resampled as a
virtual camera at the same optical centre would have seen it: another focal length, image
size and principal point, a lens with radial distortion (OpenCV's model,
:class:`~vid2sim.core.camera.Camera`), and a mounting turned by a few degrees. Turning a
camera about its optical centre changes no depth, so every pixel of the new view is exactly
a pixel of the old one (Hartley & Zisserman, Multiple View Geometry, 2nd ed., sec. 8.4.2):
the lidar truth, the GPS and the road stay valid, and only the camera changes. These clips
are what calibration is checked on: the true camera is known, the tool never sees it.

For each target pixel: undistort with the target's lens (normalised ray in the target
camera), turn into the source camera by the two mountings, project with the source's
pinhole; ``cv2.remap`` samples the source there (bilinear). Pixels that fall outside the
source image are black; :func:`draw_target_camera` only draws cameras that see inside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from vid2sim.base.errors import FormatError
from vid2sim.core.camera import Camera
from vid2sim.samples.clipfile import staged_video

# Ranges of the random target cameras (:func:`draw_target_camera`), those of consumer
# dash-cams and phones after their own cropping: horizontal field of view, barrel
# distortion k1 (phones -0.05..-0.15 after their correction, dash-cams -0.2..-0.4), small
# mounting angles and a principal point within 2 % of the image centre.
HFOV_RANGE_DEG = (50.0, 72.0)
K1_RANGE = (-0.3, -0.05)
PITCH_RANGE_DEG = (-2.0, 2.0)
YAW_RANGE_DEG = (-2.0, 2.0)
ROLL_RANGE_DEG = (-1.0, 1.0)
PRINCIPAL_OFFSET_FRAC = 0.02
WIDTHS_PX = (960, 1024, 1280)


def source_rays(target: Camera, source: Camera) -> np.ndarray:
    """(H, W, 3) viewing rays of every target pixel in the source camera's axes."""
    w, h = target.image_width, target.image_height
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pix = np.column_stack((uu.ravel(), vv.ravel()))
    rays_veh = target.pixel_rays_veh(pix)
    rays_src = rays_veh @ source.R_veh_from_cam  # R^T r, row-wise
    return rays_src.reshape(h, w, 3)


def reimage_maps(target: Camera, source: Camera) -> tuple[np.ndarray, np.ndarray]:
    """``cv2.remap`` maps: for each target pixel, the source pixel it sees (float32)."""
    rays = source_rays(target, source)
    z = rays[..., 2]
    ok = z > 1e-6
    u = np.where(ok, source.fx * rays[..., 0] / np.where(ok, z, 1.0) + source.cx, -1e4)
    v = np.where(ok, source.fy * rays[..., 1] / np.where(ok, z, 1.0) + source.cy, -1e4)
    return u.astype(np.float32), v.astype(np.float32)


def sees_inside(target: Camera, source: Camera, margin_px: float = 1.0) -> bool:
    """Whether every pixel of ``target`` falls inside the source image (no black border).

    The border of the target image is checked: its image in the source is a closed curve
    around the images of all inner pixels (the mapping is continuous and one-to-one)."""
    w, h = target.image_width - 1, target.image_height - 1
    t = np.linspace(0.0, 1.0, 64)
    border = np.concatenate([np.column_stack((w * t, np.zeros_like(t))),
                             np.column_stack((w * t, np.full_like(t, h))),
                             np.column_stack((np.zeros_like(t), h * t)),
                             np.column_stack((np.full_like(t, w), h * t))])
    uv = map_points(border, target, source)
    return bool(np.isfinite(uv).all() and uv.min() >= margin_px
                and uv[:, 0].max() <= source.image_width - 1 - margin_px
                and uv[:, 1].max() <= source.image_height - 1 - margin_px)


def map_points(points_px: np.ndarray, source: Camera, target: Camera) -> np.ndarray:
    """Source pixels -> target pixels (distortion and mounting applied); NaN behind."""
    rays = source.pixel_rays_veh(np.asarray(points_px, dtype=float).reshape(-1, 2))
    uv, ok = target.project(target.position_veh_m + 1e3 * rays)
    uv[~ok] = np.nan
    return uv


def map_box(box_px: tuple[float, float, float, float] | None, source: Camera, target: Camera,
            samples: int = 9) -> tuple[float, float, float, float] | None:
    """The box in the target image that encloses a source box's outline (sampled along its
    edges, since a distorted straight edge bows), clipped to the image; None if outside."""
    if box_px is None:
        return None
    x1, y1, x2, y2 = box_px
    t = np.linspace(0.0, 1.0, samples)
    edges = np.concatenate([np.column_stack((x1 + (x2 - x1) * t, np.full(samples, y))) for y in
                            (y1, y2)] + [np.column_stack((np.full(samples, x), y1 + (y2 - y1) * t))
                                         for x in (x1, x2)])
    uv = map_points(edges, source, target)
    if not np.isfinite(uv).all():
        return None
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    w, h = target.image_width - 1, target.image_height - 1
    if hi[0] < 0 or hi[1] < 0 or lo[0] > w or lo[1] > h:
        return None
    return (float(np.clip(lo[0], 0, w)), float(np.clip(lo[1], 0, h)),
            float(np.clip(hi[0], 0, w)), float(np.clip(hi[1], 0, h)))


@dataclass(frozen=True)
class TargetDraw:
    """How a random target camera was drawn (for the benchmark's table)."""

    seed: int
    hfov_deg: float
    camera: Camera


def target_camera(source: Camera, width_px: int, height_px: int, hfov_deg: float,
                  dist: tuple[float, ...], pitch_deg: float = 0.0, yaw_deg: float = 0.0,
                  roll_deg: float = 0.0, principal_offset_px: tuple[float, float] = (0.0, 0.0)
                  ) -> Camera:
    """A camera at the source's optical centre and height with the given lens and mounting
    (angles relative to the vehicle, as the source's are)."""
    f = (width_px / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
    return Camera(image_width=int(width_px), image_height=int(height_px), fx=f, fy=f,
                  cx=(width_px - 1) / 2.0 + principal_offset_px[0],
                  cy=(height_px - 1) / 2.0 + principal_offset_px[1], dist=tuple(dist),
                  height_m=source.height_m, pitch_deg=source.pitch_deg + pitch_deg,
                  yaw_deg=source.yaw_deg + yaw_deg, roll_deg=source.roll_deg + roll_deg)


def draw_target_camera(source: Camera, seed: int, distorted: bool = True,
                       tries: int = 200,
                       hfov_range_deg: tuple[float, float] = HFOV_RANGE_DEG) -> TargetDraw:
    """A random target camera that sees only inside the source image.

    Field of view, width, distortion (``distorted``: k1 drawn, k2 = -k1 / 10 as real
    lenses' second term is small against the first; else a pinhole), mounting angles and
    principal point are drawn from the module's ranges (the field of view from
    ``hfov_range_deg``: narrower than the source's); the height is the tallest that
    the source's vertical field of view allows (at most 0.42 of the width: dash-cam
    strips are 16:9 or wider after their bonnet crop).
    """
    rng = np.random.default_rng(seed)
    for _ in range(tries):
        hfov = float(rng.uniform(*hfov_range_deg))
        width = int(rng.choice(WIDTHS_PX))
        k1 = float(rng.uniform(*K1_RANGE)) if distorted else 0.0
        dist = (k1, -k1 / 10.0, 0.0, 0.0, 0.0) if distorted else (0.0,) * 5
        angles = [float(rng.uniform(*r)) for r in (PITCH_RANGE_DEG, YAW_RANGE_DEG,
                                                    ROLL_RANGE_DEG)]
        off = tuple(float(v) for v in rng.uniform(-PRINCIPAL_OFFSET_FRAC, PRINCIPAL_OFFSET_FRAC,
                                                   2) * width)
        for height in range(int(0.42 * width) // 2 * 2, 160, -16):
            cam = target_camera(source, width, height, hfov, dist, *angles,
                                principal_offset_px=(off[0], off[1] * height / width))
            if sees_inside(cam, source):
                return TargetDraw(seed=seed, hfov_deg=hfov, camera=cam)
    raise ValueError(f"no target camera inside the source image in {tries} draws")


def reimage_frame(frame_bgr: np.ndarray, maps: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """One source frame seen through the target camera (bilinear, black outside)."""
    return cv2.remap(frame_bgr, maps[0], maps[1], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def write_reimaged_video(video: Path, source: Camera, target: Camera, out_path: Path,
                         fps: float | None = None) -> Path:
    """Stream ``video`` through the target camera into ``out_path`` (mp4v; written to a
    hidden file beside it and renamed when complete)."""
    video, out_path = Path(video), Path(out_path)
    cap = cv2.VideoCapture(str(video))
    if not cap.isOpened():
        raise FormatError(video, "OpenCV cannot open this video")
    rate = fps or float(cap.get(cv2.CAP_PROP_FPS)) or 10.0
    width = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
    height = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    src = source if (source.image_width, source.image_height) == (width, height) else replace(
        source, image_width=width, image_height=height)
    maps = reimage_maps(target, src)
    try:
        with staged_video(out_path, (target.image_width, target.image_height), rate) as writer:
            while True:
                ok, frame = cap.read()
                if not ok:
                    break
                writer.write(reimage_frame(frame, maps))
    finally:
        cap.release()
    return out_path
