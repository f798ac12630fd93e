"""Semi-synthetic test clips with exact truth: a real car composited into a real drive.

A car seen from behind is cut out of a labelled KITTI tracking frame (its 3D label gives its
size and the range of its rear face) and pasted into every frame of the KITTI raw drive
``2011_09_26_drive_0001`` (``../shared/data/kitti_raw_0001/video.mp4``) as a lead vehicle at a
chosen trajectory. The truth of every frame (range of the rear, lateral offset of the centre,
range rate) is therefore exact, while the background, the road, the camera and the vehicle's
pixels are all real: the closest stand-in for a recorded clip with lidar range to a lead.

Geometry of the paste. The car's rear is a plane facing the camera, so between the source and
the target camera it maps by a similarity: scale ``s = (f_target / f_source) * (Z_source /
z_target)`` (``Z_source`` the depth of the rear face in the source camera from the label,
``z_target`` its depth at the chosen range; horizontally corrected for the few degrees the source
car is turned, :attr:`CarCutout.face_scale`) and a shift that puts the bottom centre of the rear
(source: the middle of the car's outline on the row where the label's rear face, through
KITTI's ``P2``, meets the road; target: :meth:`Camera.project` of the road point below the
middle of the rear) on top of each other. So the rear lands where the target camera projects
it. What the similarity cannot reproduce: the strip of roof that shows above the rear window
depends on the height of each camera above the car (a few pixels at 8 m, under one beyond
20 m), and the side a laterally offset car shows (none within the +-0.4 m of the lead
trajectories: a side shows only once |lateral| > width / 2). The crop is therefore cut to the
columns of the car's rear: the flank a source car shows from a neighbouring lane is not pasted.

What the pasted car is not. Its outline is the rear alone, 1.45 m wide for the car at hand,
narrower than its label's 1.57 m box (which takes in the flanks at the wheel arches) and without
mirrors, so its box is narrower than a real car's of the same model seen from behind. The source
car stood in the shade of a wall: it is darker than the sunlit cars of the drive, and it casts
no shadow on the road. The detector's scores on it match those of real KITTI cars of the same box
height (see ``benchmarks/bench_composite.py``).

Body pitch. The ego body pitches on its suspension and with the road, and every real object in
the video moves with it. The target camera of each frame gets the OXTS pitch of that frame
relative to the drive's mean (positive = nose down, as the camera's ``pitch_deg``), so the pasted
car moves with the road like the parked cars do (the ranging's per-frame pitch estimate compares
exactly these cues). That the OXTS pitch is the image's motion is checked on the video itself:
the frame-to-frame vertical shift of the far background (phase correlation) follows
``-f * d(pitch)`` with correlation -0.98 and the same spread (0.70 vs 0.73 px).

Occlusion. The paste is drawn over the background: right for the far road, the tram and the
parked cars at the sides (all further away or beside the ego lane); the trajectories stay in the
ego lane (|lateral| <= 0.4 m), where nothing in this drive is nearer than the lead.

Pure functions do the geometry and pixels; :func:`load_cutout` reads the KITTI frame and
:func:`write_composite_clip` streams the video one frame at a time into a temporary file that
is renamed when complete.

KITTI material: CC BY-NC-SA 3.0, Geiger, Lenz, Stiller, Urtasun, "Vision meets Robotics: The
KITTI Dataset", IJRR 2013. It is read at run time and never copied into the project.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from vid2sim.camera import Camera, fit_camera_to_frames, load_camera, parse_kitti_calib
from vid2sim.detect.boxes import iou_matrix
from vid2sim.detect.external import KittiLabel, read_kitti_tracking_labels
from vid2sim.errors import InputError
from vid2sim.fileio import read_input_text, write_text_atomic
from vid2sim.geo.readers import OXTS_PITCH, read_kitti_oxts_table

# A rear view: the car heads within this angle of the camera axis [deg].
MAX_REAR_YAW_DEG = 15.0
MIN_CUTOUT_HEIGHT_PX = 40.0
# Width of the soft edge of the cut-out [source px] (Gaussian sigma of the alpha).
FEATHER_SIGMA_PX = 1.2
# Silhouette prior of a car from behind (fractions of the rear face): the body is full width
# up to the belt line, the cabin above it narrows towards the roof.
_BELT_FRACTION = 0.45  # belt line height above the bottom, as a share of the face height
_ROOF_INSET = 0.13  # inset of the roof corners, as a share of the face width

# The drive's frames: the KITTI raw left grayscale camera at 10 Hz.
DEFAULT_FPS = 10.0


# --------------------------------------------------------------------------- the cut-out


@dataclass(frozen=True)
class CarCutout:
    """A car's rear view ready to paste.

    Parameters
    ----------
    gray : ndarray
        (H, W) float32 intensities of the crop [0, 255].
    alpha : ndarray
        (H, W) float32 opacity [0, 1], feathered at the silhouette.
    anchor_px : tuple
        Bottom centre of the rear face in crop pixels (u, v): the road point below the rear.
    rear_box_px : tuple
        The rear face's box (x1, y1, x2, y2) in crop pixels.
    depth_m : float
        Depth of the rear face in the source camera [m].
    focal_px : float
        Source focal length [px].
    width_m, height_m, length_m : float
        The label's 3D size [m].
    source : str
        Which labelled object this is (sequence/frame/track).
    face_scale : float
        Horizontal correction of the source's perspective (see :func:`cut_out_car`).
    """

    gray: np.ndarray
    alpha: np.ndarray
    anchor_px: tuple[float, float]
    rear_box_px: tuple[float, float, float, float]
    depth_m: float
    focal_px: float
    width_m: float
    height_m: float
    length_m: float
    source: str
    face_scale: float = 1.0

    @property
    def visible_width_m(self) -> float:
        """Width of the pasted outline [m] (the car's rear, narrower than the 3D box)."""
        return ((self.rear_box_px[2] - self.rear_box_px[0]) * self.face_scale * self.depth_m
                / self.focal_px)


def read_kitti_projection(calib_path: Path, cam: int = 2) -> np.ndarray:
    """The 3x4 rectified projection ``P{cam}`` of a KITTI tracking ``calib/SSSS.txt``.

    Labels are in the rectified reference camera (camera 0); ``P2`` carries the offset of the
    colour camera (about 6 cm, several pixels at a few metres), which :func:`load_camera`'s
    pinhole drops.
    """
    values = parse_kitti_calib(read_input_text(Path(calib_path))).get(f"P{cam}")
    if values is None or values.size != 12:
        raise InputError(calib_path, f"no 3x4 projection P{cam}")
    return values.reshape(3, 4)


def label_corners(label: KittiLabel, yaw_rad: float) -> np.ndarray:
    """(8, 3) corners of a label's 3D box in rectified camera coordinates (x right, y down,
    z forward); rows 0-3 are the rear face, rows 4-7 the front.

    ``yaw_rad`` is the label's ``rotation_y`` (heading about the camera's y axis; -pi/2 drives
    straight away from the camera).
    """
    h, w, ll = label.size_hwl_m
    # Object frame: x along the heading, y down, z across; the location is the bottom centre.
    local = np.array([[sx * ll / 2, sy, sz * w / 2]
                      for sx in (-1, 1) for sy in (0.0, -h) for sz in (1, -1)])
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return local @ rot.T + np.asarray(label.location_m)


def read_labels_with_yaw(path: Path) -> dict[int, list[tuple[KittiLabel, float]]]:
    """KITTI tracking labels (frame -> [(label, rotation_y)]); ``rotation_y`` is the heading
    about the camera's y axis [rad] (-pi/2: driving away from the camera)."""
    labels = read_kitti_tracking_labels(path)
    yaws: dict[tuple[int, int], float] = {}
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        f = line.split()
        if len(f) >= 17:
            yaws[(int(f[0]), int(f[1]))] = float(f[16])
    return {fr: [(lb, yaws.get((fr, lb.track_id), float("nan"))) for lb in lbs]
            for fr, lbs in labels.items()}


def is_rear_view(label: KittiLabel, yaw_rad: float,
                 min_height_px: float = MIN_CUTOUT_HEIGHT_PX) -> bool:
    """A car seen from behind, whole and unoccluded: type Car, not truncated, not occluded,
    heading within :data:`MAX_REAR_YAW_DEG` of straight away, box at least ``min_height_px``."""
    h = label.box_px[3] - label.box_px[1]
    off = abs(math.degrees(yaw_rad) + 90.0)
    return (label.type == "Car" and label.truncated == 0 and label.occluded == 0
            and h >= min_height_px and off <= MAX_REAR_YAW_DEG)


def _rear_face(label: KittiLabel, yaw_rad: float, proj: np.ndarray
               ) -> tuple[np.ndarray, float, np.ndarray]:
    """Projected rear-face corners (4, 2), their mean depth [m] and the projected bottom
    centre of the rear face (2,)."""
    corners = label_corners(label, yaw_rad)
    rear = corners[:4]
    # The face turned towards the camera is the one nearer to it.
    front = corners[4:]
    if front[:, 2].mean() < rear[:, 2].mean():
        rear = front
    hom = np.column_stack((rear, np.ones(4))) @ proj.T
    uv = hom[:, :2] / hom[:, 2:3]
    bottom_centre = rear[np.isclose(rear[:, 1], rear[:, 1].max())].mean(axis=0)
    b = proj @ np.append(bottom_centre, 1.0)
    return uv, float(hom[:, 2].mean()), b[:2] / b[2]


def _silhouette_prior(shape: tuple[int, int], face: tuple[float, float, float, float],
                      top_px: float) -> np.ndarray:
    """uint8 mask of a car's rear outline within the rear face columns: full width below the
    belt line, a cabin narrowing to the roof above it."""
    x1, _, x2, y2 = face
    wd = x2 - x1
    belt = y2 - _BELT_FRACTION * (y2 - top_px)
    poly = np.array([[x1, y2], [x1, belt], [x1 + _ROOF_INSET * wd, top_px],
                     [x2 - _ROOF_INSET * wd, top_px], [x2, belt], [x2, y2]])
    mask = np.zeros(shape, np.uint8)
    cv2.fillPoly(mask, [np.round(poly * 16).astype(np.int32)], 255, lineType=cv2.LINE_AA,
                 shift=4)
    return mask


def cut_out_car(image_bgr: np.ndarray, label: KittiLabel, yaw_rad: float, proj: np.ndarray,
                source: str = "", columns_px: tuple[float, float] | None = None,
                margin_px: int = 6) -> CarCutout:
    """Cut a rear-view car out of a KITTI frame.

    The crop spans the label's 2D box vertically (roof to the road) and the car's rear
    horizontally: ``columns_px`` where given (the visible outline read off the image), else
    the label's projected rear face; a flank seen from the neighbouring lane is left out. The
    silhouette is GrabCut's foreground inside the label box (a colour model of car against
    background) intersected with a car-rear outline prior (which removes background of
    similar colour that GrabCut takes in), with the body below the belt line filled, opened
    and closed, then feathered with a Gaussian edge.

    Parameters
    ----------
    image_bgr : ndarray
        The KITTI ``image_02`` frame.
    label : KittiLabel
        The car's label in that frame.
    yaw_rad : float
        Its ``rotation_y``.
    proj : ndarray
        The frame's 3x4 projection ``P2``.
    source : str
        A name for the cut-out (reports).
    columns_px : tuple, optional
        Left and right image columns of the car's rear outline [px].
    margin_px : int
        Background kept around the car in the crop (room for the feathered edge).

    Returns
    -------
    CarCutout
        ``anchor_px`` is the middle of the columns on the row of the rear face's bottom;
        ``face_scale`` corrects the source's slight yaw (a rear face turned by a few degrees
        off a side position looks a few per cent wider than one square to the camera).
    """
    uv, depth, _ = _rear_face(label, yaw_rad, proj)
    bx1, by1, bx2, by2 = label.box_px
    fx1, fy1 = float(uv[:, 0].min()), float(uv[:, 1].min())
    fx2, fy2 = float(uv[:, 0].max()), float(uv[:, 1].max())
    h3, w3, l3 = label.size_hwl_m
    face_scale = (proj[0, 0] * w3 / depth) / (fx2 - fx1)
    if columns_px is not None:
        fx1, fx2 = (float(c) for c in columns_px)
    else:
        fx1, fx2 = max(fx1, bx1), min(fx2, bx2)
    top = min(by1, fy1)
    bottom = max(fy2, by2)
    hgt, wid = image_bgr.shape[:2]
    cx1 = max(math.floor(fx1) - margin_px, 0)
    cy1 = max(math.floor(top) - margin_px, 0)
    cx2 = min(math.ceil(fx2) + margin_px, wid - 1)
    cy2 = min(math.ceil(bottom) + margin_px, hgt - 1)

    # GrabCut on the frame with the label box as the foreground rectangle.
    rect = (int(bx1), int(by1), math.ceil(bx2 - bx1), math.ceil(by2 - by1))
    gc_mask = np.zeros((hgt, wid), np.uint8)
    bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
    cv2.setRNGSeed(0)
    cv2.grabCut(image_bgr, gc_mask, rect, bgd, fgd, 5, cv2.GC_INIT_WITH_RECT)
    fg = np.where((gc_mask == cv2.GC_FGD) | (gc_mask == cv2.GC_PR_FGD), 255, 0).astype(np.uint8)
    prior = _silhouette_prior((hgt, wid), (fx1, fy1, fx2, fy2), top)
    mask = cv2.bitwise_and(fg, prior)
    # The body below the belt line is solid: fill GrabCut's holes (dark bumper, plate).
    belt = round(fy2 - _BELT_FRACTION * (fy2 - top))
    body = np.zeros_like(mask)
    body[belt:math.ceil(fy2) + 1] = prior[belt:math.ceil(fy2) + 1]
    mask = cv2.bitwise_or(mask, body)
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    mask = cv2.morphologyEx(cv2.morphologyEx(mask, cv2.MORPH_OPEN, k), cv2.MORPH_CLOSE, k)
    # Nothing outside the rear columns or below the rear face's bottom (the road).
    cols = np.arange(wid)[None, :]
    rows = np.arange(hgt)[:, None]
    inside = (cols >= fx1) & (cols <= fx2) & (rows <= fy2)
    mask = np.where(inside, mask, 0).astype(np.float32) / 255.0
    alpha = cv2.GaussianBlur(mask, (0, 0), FEATHER_SIGMA_PX)

    gray = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    sl = (slice(cy1, cy2 + 1), slice(cx1, cx2 + 1))
    # Pixel coordinates as the projection gives them (integer = pixel centre), crop-relative.
    anchor = (0.5 * (fx1 + fx2) - cx1, fy2 - cy1)
    return CarCutout(
        gray=np.ascontiguousarray(gray[sl]), alpha=np.ascontiguousarray(alpha[sl]),
        anchor_px=(float(anchor[0]), float(anchor[1])),
        rear_box_px=(fx1 - cx1, top - cy1, fx2 - cx1, fy2 - cy1),
        depth_m=depth, focal_px=float(proj[0, 0]), width_m=float(w3), height_m=float(h3),
        length_m=float(l3), source=source, face_scale=float(face_scale))


# The cars at hand: name -> (sequence, frame, track id, columns of the rear outline or None).
# "polo" is a small hatchback parked 6.6 m ahead on the right (rear 164 x 156 px), the only
# labelled car of the frames at hand seen from behind, whole and unoccluded at a useful size.
# Its columns are read off the image: the label's projected rear face reaches 15 px past the
# car's right side (a wall there) and starts 8 px inside the left tail light.
# The other candidates fail: 0001/20 object 5 stands behind a post, 0016/2 objects 1 and 2
# behind a railing, and 0016/2 object 3 (a dark car 35 m ahead, 30 px high) is too small for
# GrabCut to find its outline and would be upscaled at any nearer range.
CARS: dict[str, tuple[str, int, int, tuple[float, float] | None]] = {
    "polo": ("0001", 10, 2, (838.0, 1002.0)),
}


def load_cutout(tracking_dir: Path, car: str = "polo", require_rear_view: bool = True
                ) -> CarCutout:
    """Read a KITTI tracking frame and its label and cut out a car of :data:`CARS`.

    Raises
    ------
    InputError
        If the frame or label is missing, or the car is not a whole rear view and
        ``require_rear_view`` is set.
    """
    seq, frame, track, columns = CARS[car]
    tracking_dir = Path(tracking_dir)
    img_path = tracking_dir / "image_02" / seq / f"{frame:06d}.png"
    image = cv2.imread(str(img_path), cv2.IMREAD_COLOR)
    if image is None:
        raise InputError(img_path, "cannot read this KITTI frame")
    label_path = tracking_dir / "label_02" / f"{seq}.txt"
    found = [(lb, yaw) for lb, yaw in read_labels_with_yaw(label_path).get(frame, [])
             if lb.track_id == track]
    if not found:
        raise InputError(label_path, f"no object {track} in frame {frame}")
    label, yaw = found[0]
    if require_rear_view and not is_rear_view(label, yaw):
        raise InputError(img_path, f"object {track} is not a whole car seen from behind")
    calib = tracking_dir / "calib" / f"{seq}.txt"
    proj = read_kitti_projection(calib)
    if abs(load_camera(calib).fx - proj[0, 0]) > 1e-6:  # the same calibration, read twice
        raise InputError(calib, "P2 and the camera disagree on the focal length")
    return cut_out_car(image, label, yaw, proj, columns_px=columns,
                       source=f"kitti_tracking {seq}/{frame:06d} object {track} ({car})")


# --------------------------------------------------------------------------- the paste


def paste_transform(cutout: CarCutout, camera: Camera, range_m: float, lateral_m: float
                    ) -> np.ndarray:
    """The 2x3 affine map from crop pixels to target pixels for a car at (``range_m``,
    ``lateral_m``): ``range_m`` is the vehicle-frame x of its rear, ``lateral_m`` the y of its
    centre.

    Scale ``(f_t / f_s) * (Z_s / z_t)`` (horizontally times ``face_scale``), shift so the
    crop's anchor lands on the projection of the road point below the middle of the rear.
    """
    ground = np.array([[range_m, lateral_m, 0.0]])
    uv, ok = camera.project(ground)
    if not ok.all():
        raise ValueError(f"a car at range {range_m} m is not in front of the camera")
    depth = float(camera.vehicle_to_camera(ground)[0, 2])
    sy = (camera.fy / cutout.focal_px) * (cutout.depth_m / depth)
    sx = sy * cutout.face_scale * camera.fx / camera.fy
    return np.array([[sx, 0.0, float(uv[0, 0]) - sx * cutout.anchor_px[0]],
                     [0.0, sy, float(uv[0, 1]) - sy * cutout.anchor_px[1]]])


def paste_car(frame_bgr: np.ndarray, cutout: CarCutout, camera: Camera, range_m: float,
              lateral_m: float) -> np.ndarray:
    """``frame_bgr`` with the car composited at (``range_m``, ``lateral_m``) (a new array).

    The crop is low-pass filtered before it is shrunk (no aliasing of the number plate and
    edges), warped with the exact sub-pixel map of :func:`paste_transform` and blended by its
    alpha; the car's gray values go into all three channels (the drive is grayscale).
    """
    m = paste_transform(cutout, camera, range_m, lateral_m)
    sx, sy = m[0, 0], m[1, 1]
    gray, alpha = cutout.gray, cutout.alpha
    if min(sx, sy) < 1.0:
        sig = [0.5 * math.sqrt(max(1.0 / v ** 2 - 1.0, 0.0)) for v in (sx, sy)]
        gray = cv2.GaussianBlur(gray, (0, 0), sigmaX=max(sig[0], 1e-3), sigmaY=max(sig[1], 1e-3))
        alpha = cv2.GaussianBlur(alpha, (0, 0), sigmaX=max(sig[0], 1e-3),
                                 sigmaY=max(sig[1], 1e-3))
    hgt, wid = frame_bgr.shape[:2]
    ch, cw = gray.shape
    # Work on the target window covered by the crop only.
    x0 = max(math.floor(m[0, 2]) - 1, 0)
    y0 = max(math.floor(m[1, 2]) - 1, 0)
    x1 = min(math.ceil(m[0, 2] + sx * cw) + 1, wid)
    y1 = min(math.ceil(m[1, 2] + sy * ch) + 1, hgt)
    out = frame_bgr.copy()
    if x1 <= x0 or y1 <= y0:
        return out
    local = m.copy()
    local[0, 2] -= x0
    local[1, 2] -= y0
    size = (x1 - x0, y1 - y0)
    g = cv2.warpAffine(gray, local, size, flags=cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_CONSTANT)
    a = cv2.warpAffine(alpha, local, size, flags=cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    roi = out[y0:y1, x0:x1].astype(np.float32)
    blended = roi * (1.0 - a[..., None]) + g[..., None] * a[..., None]
    out[y0:y1, x0:x1] = np.clip(np.rint(blended), 0, 255).astype(np.uint8)
    return out


def truth_box(cutout: CarCutout, camera: Camera, range_m: float, lateral_m: float,
              width_m: float | None = None) -> tuple[float, float, float, float] | None:
    """The pixel box of the car's 3D box at (``range_m``, ``lateral_m``), aligned with the ego
    (:meth:`Camera.project_box`, clipped to the image); ``width_m`` replaces the label's
    width (e.g. :attr:`CarCutout.visible_width_m` for the box of the pasted outline)."""
    centre = np.array([range_m + cutout.length_m / 2.0, lateral_m, 0.0])
    return camera.project_box(centre, cutout.length_m, width_m or cutout.width_m,
                              cutout.height_m)


# --------------------------------------------------------------------------- trajectories


@dataclass(frozen=True)
class LeadTruth:
    """The lead's exact trajectory at the frame times.

    ``range_m``: x of its rear in the ego vehicle frame; ``lateral_m``: y of its centre (left
    positive); ``range_rate_mps``: d(range)/dt; ``rel_accel_mps2``: d(range rate)/dt.
    """

    t_s: np.ndarray
    range_m: np.ndarray
    lateral_m: np.ndarray
    range_rate_mps: np.ndarray
    rel_accel_mps2: np.ndarray
    seed: int


def _moving_average(x: np.ndarray, n: int) -> np.ndarray:
    if n <= 1:
        return x
    pad = np.concatenate((np.full(n, x[0]), x, np.full(n, x[-1])))
    return np.convolve(pad, np.ones(n) / n, mode="same")[n:-n]


def lead_profile(seed: int, n_frames: int, fps: float = DEFAULT_FPS, *,
                 range_bounds_m: tuple[float, float] = (8.0, 45.0), max_speed_mps: float = 6.0,
                 max_brake_mps2: float = 4.0, max_lateral_m: float = 0.4,
                 dt_s: float = 0.005) -> LeadTruth:
    """A seeded lead trajectory with one braking and one opening phase.

    The relative acceleration is a sequence of phases (hold, brake at ``max_brake_mps2`` - 0.8 to ``max_brake_mps2``
    until closing at 3 to ``max_speed_mps``, hold, accelerate at 1.5 to 3 m/s^2 until opening
    at 2 to ``max_speed_mps``, hold, in random order brake-first or open-first), smoothed over
    0.3 s (jerk-limited like a driver's pedal), integrated exactly on a fine grid; the start
    range is drawn from the interval that keeps the whole trajectory in ``range_bounds_m``.
    The lateral offset is a slow sine (period 6-15 s) about an offset, within
    +-``max_lateral_m``.

    Returns
    -------
    LeadTruth
        Sampled at frame times ``i / fps``.
    """
    rng = np.random.default_rng(seed)
    duration = n_frames / fps
    t = np.arange(0.0, duration + dt_s, dt_s)
    lo, hi = range_bounds_m
    for _attempt in range(200):
        brake = -rng.uniform(max_brake_mps2 - 0.8, max_brake_mps2)
        accel = rng.uniform(1.5, 3.0)
        v_close = -rng.uniform(3.0, max_speed_mps)
        v_open = rng.uniform(2.0, max_speed_mps)
        v0 = rng.uniform(-1.0, 1.0)
        holds = rng.uniform(0.3, 2.0, size=3)
        order = [(brake, v_close), (accel, v_open)]
        if rng.random() < 0.5:
            order.reverse()
        # Piecewise-constant acceleration: hold, phase 1, hold, phase 2, hold...
        a = np.zeros_like(t)
        v = v0
        tc = holds[0]
        for (acc, target), hold in zip(order, holds[1:], strict=True):
            dur = (target - v) / acc
            a[(t >= tc) & (t < tc + dur)] = acc
            v = target
            tc += dur + hold
        if tc > duration:
            continue
        a = _moving_average(a, max(1, round(0.3 / dt_s)))
        vel = v0 + np.concatenate(([0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * dt_s)))
        disp = np.concatenate(([0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt_s)))
        r_lo, r_hi = lo - disp.min(), hi - disp.max()
        if r_hi <= r_lo or np.abs(vel).max() > max_speed_mps + 1e-9:
            continue
        r0 = rng.uniform(r_lo + 0.1 * (r_hi - r_lo), r_hi - 0.1 * (r_hi - r_lo))
        rng_m = r0 + disp
        break
    else:  # pragma: no cover - the phases above always fit within a few attempts
        raise RuntimeError(f"no lead trajectory within {range_bounds_m} m for seed {seed}")
    amp = rng.uniform(0.05, 0.25)
    offset = rng.uniform(-(max_lateral_m - amp), max_lateral_m - amp)
    period, phase = rng.uniform(6.0, 15.0), rng.uniform(0, 2 * math.pi)
    t_f = np.arange(n_frames) / fps
    idx = np.clip(np.rint(t_f / dt_s).astype(int), 0, len(t) - 1)
    lateral = offset + amp * np.sin(2 * math.pi * t_f / period + phase)
    return LeadTruth(t_s=t_f, range_m=rng_m[idx], lateral_m=lateral, range_rate_mps=vel[idx],
                     rel_accel_mps2=a[idx], seed=seed)


# --------------------------------------------------------------------------- the drive


def read_oxts_pitch(raw_dir: Path) -> np.ndarray:
    """OXTS pitch of every frame of a KITTI raw drive [rad] (positive = nose down)."""
    return read_kitti_oxts_table(raw_dir)[:, OXTS_PITCH]


def frame_cameras(camera: Camera, pitch_rad: np.ndarray | None, n_frames: int
                  ) -> list[Camera]:
    """The target camera of each frame: ``camera`` pitched by the body pitch relative to the
    drive's mean (None: the camera unchanged in every frame)."""
    if pitch_rad is None:
        return [camera] * n_frames
    rel = np.degrees(np.asarray(pitch_rad, dtype=float) - float(np.mean(pitch_rad)))
    if rel.size < n_frames:
        raise InputError(None, f"{rel.size} pitch samples for {n_frames} frames")
    return [camera.with_pitch(camera.pitch_deg + float(d)) for d in rel[:n_frames]]


@dataclass(frozen=True)
class CompositeClip:
    """A written clip: the video, its truth file and the truth itself."""

    video: Path
    truth_json: Path
    truth: LeadTruth
    boxes_px: list[tuple[float, float, float, float] | None]
    camera: Camera
    cameras: list[Camera]
    cutout_source: str


def _open_writer(out_path: Path, width: int, height: int, fps: float
                 ) -> tuple[cv2.VideoWriter, Path]:
    fourcc = "mp4v" if out_path.suffix.lower() == ".mp4" else "MJPG"
    tmp = out_path.parent / f".{out_path.stem}.partial{out_path.suffix}"
    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*fourcc), fps, (width, height))
    if not writer.isOpened():
        writer.release()
        tmp.unlink(missing_ok=True)
        raise RuntimeError(f"OpenCV cannot write {fourcc} video to {tmp}")
    return writer, tmp


def write_composite_clip(raw_dir: Path, cutout: CarCutout, truth: LeadTruth, out_path: Path,
                         *, use_body_pitch: bool = True) -> CompositeClip:
    """Composite the car into every frame of the drive and write the clip and its truth.

    Frames are read, pasted and written one at a time; the video goes to a hidden temporary
    file beside ``out_path`` renamed over it when complete, and ``<out_path>.truth.json``
    (per frame: t_s, range_m, lateral_m, range_rate_mps, rel_accel_mps2, box_px) is written
    atomically after it. ``box_px`` is the box of the pasted outline: :func:`truth_box` with
    the cut-out's visible width, in the frame's pitched camera.

    Parameters
    ----------
    raw_dir : Path
        The KITTI raw drive folder (``video.mp4``, ``camera.yaml``, ``oxts/``).
    cutout : CarCutout
        The car.
    truth : LeadTruth
        Its trajectory, one sample per video frame.
    out_path : Path
        ``.mp4`` (mp4v) or ``.avi`` (MJPG).
    use_body_pitch : bool
        Move the car with the OXTS body pitch (see the module docstring).
    """
    raw_dir, out_path = Path(raw_dir), Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    video = raw_dir / "video.mp4"
    cap = cv2.VideoCapture(str(video))
    if not cap.isOpened():
        raise InputError(video, "OpenCV cannot open this video")
    width = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
    height = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    fps = float(cap.get(cv2.CAP_PROP_FPS)) or DEFAULT_FPS
    n_frames = len(truth.t_s)
    camera, _ = fit_camera_to_frames(load_camera(raw_dir / "camera.yaml"), width, height)
    pitch = read_oxts_pitch(raw_dir) if use_body_pitch else None
    cams = frame_cameras(camera, pitch, n_frames)
    boxes: list[tuple[float, float, float, float] | None] = []
    writer, tmp = _open_writer(out_path, width, height, fps)
    try:
        for i in range(n_frames):
            ok, frame = cap.read()
            if not ok:
                raise InputError(video, f"video ends at frame {i}, truth has {n_frames}")
            r, y = float(truth.range_m[i]), float(truth.lateral_m[i])
            writer.write(paste_car(frame, cutout, cams[i], r, y))
            boxes.append(truth_box(cutout, cams[i], r, y, cutout.visible_width_m))
    except BaseException:
        writer.release()
        tmp.unlink(missing_ok=True)
        raise
    finally:
        cap.release()
    writer.release()
    os.replace(tmp, out_path)
    truth_path = out_path.with_name(out_path.name + ".truth.json")
    write_text_atomic(truth_path, truth_to_json(truth, boxes, cutout, use_body_pitch))
    return CompositeClip(out_path, truth_path, truth, boxes, camera, cams, cutout.source)


def truth_to_json(truth: LeadTruth, boxes: list, cutout: CarCutout, body_pitch: bool) -> str:
    """The truth file's text: car, seed and one record per frame."""
    frames = [{"frame": i, "t_s": round(float(truth.t_s[i]), 6),
               "range_m": round(float(truth.range_m[i]), 6),
               "lateral_m": round(float(truth.lateral_m[i]), 6),
               "range_rate_mps": round(float(truth.range_rate_mps[i]), 6),
               "rel_accel_mps2": round(float(truth.rel_accel_mps2[i]), 6),
               "box_px": None if boxes[i] is None else [round(v, 2) for v in boxes[i]]}
              for i in range(len(truth.t_s))]
    doc = {"car": cutout.source, "seed": truth.seed, "body_pitch_from_oxts": body_pitch,
           "size_hwl_m": [cutout.height_m, cutout.width_m, cutout.length_m],
           "frames": frames}
    return json.dumps(doc, indent=1) + "\n"



# --------------------------------------------------------------------------- scoring


def box_iou(a: tuple[float, float, float, float], b: tuple[float, float, float, float]
            ) -> float:
    """Intersection over union of two (x1, y1, x2, y2) boxes (the tracker's IoU)."""
    return float(iou_matrix(np.array([a]), np.array([b]))[0, 0])


@dataclass(frozen=True)
class LeadScore:
    """Lead figures of one clip against the composite's truth.

    ``presence``: share of all frames whose chosen lead is the composited car (box IoU with
    the truth projection >= the threshold); ``range_rel_err_median``: median |range error| /
    true range and ``range_bias_median`` the median signed one, over those frames;
    ``range_rate_rmse_mps`` over those of them with a rate; ``tracked_share``: frames where any
    track is on the car; ``car_track_ids``: the tracks that were (more than one: id switches).
    """

    n_frames: int
    presence: float
    range_rel_err_median: float
    range_bias_median: float
    range_rate_rmse_mps: float
    tracked_share: float
    car_track_ids: tuple[int, ...]
    wrong_lead_frames: int


def score_lead(boxes: list, truth: LeadTruth, truth_boxes: list, min_iou: float = 0.5
               ) -> LeadScore:
    """Score ranged boxes (:class:`vid2sim.records.RangedBox`) of a composite clip.

    Parameters
    ----------
    boxes : list of RangedBox
        Output of the ranging for the clip.
    truth : LeadTruth
        The composited car's trajectory.
    truth_boxes : list
        Its pixel box per frame (None where off the image), e.g. :func:`truth_box` with the
        cut-out's visible width.
    min_iou : float
        A box is on the car from this IoU with the truth box.
    """
    n = len(truth.t_s)
    by_frame: dict[int, list] = {}
    for b in boxes:
        by_frame.setdefault(b.frame, []).append(b)
    rel, signed, rate_err = [], [], []
    present = tracked = wrong = 0
    ids: set[int] = set()
    for i in range(n):
        tb = truth_boxes[i]
        rows = by_frame.get(i, [])
        on_car = [b for b in rows
                  if tb is not None and box_iou((b.x1, b.y1, b.x2, b.y2), tb) >= min_iou]
        tracked += bool(on_car)
        ids.update(b.track_id for b in on_car)
        lead = [b for b in rows if b.is_lead]
        if not lead:
            continue
        if not any(b in on_car for b in lead):
            wrong += 1
            continue
        b = lead[0]
        present += 1
        r = float(truth.range_m[i])
        rel.append(abs(b.range_m - r) / r)
        signed.append((b.range_m - r) / r)
        if np.isfinite(b.range_rate_mps):
            rate_err.append(b.range_rate_mps - float(truth.range_rate_mps[i]))
    nan = float("nan")
    return LeadScore(
        n_frames=n, presence=present / n if n else nan,
        range_rel_err_median=float(np.median(rel)) if rel else nan,
        range_bias_median=float(np.median(signed)) if signed else nan,
        range_rate_rmse_mps=float(np.sqrt(np.mean(np.square(rate_err)))) if rate_err else nan,
        tracked_share=tracked / n if n else nan, car_track_ids=tuple(sorted(ids)),
        wrong_lead_frames=wrong)
