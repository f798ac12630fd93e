"""A real car cut out of a labelled KITTI frame and pasted into another camera's frame.

A car seen from behind is cut out of a labelled KITTI tracking frame (its 3D label gives its
size and the range of its rear face); :func:`paste_car` composites it into a target frame at a
chosen range and lateral offset, and :func:`truth_box` is the box it then covers.

Geometry of the paste. A car seen from behind is drawn as a plane facing the camera, mapped
between the source and the target camera by a similarity. The plane is put where the parts
that make a detector's box are: the tyres' contact with the road (the box's bottom) and the
body's widest section over the rear axle (its sides), some way ahead of the rear face. So the
cut-out keeps the car's real bottom (tyres, the dark road under the car) down to the tyres'
contact row, read off the source image, whose depth on the label's ground plane is the
contact's depth ``Z_c`` (:attr:`CarCutout.contact_m` ahead of the label's rear face); the scale
is ``s = (f_target / f_source) * (Z_c / z_target)`` with ``z_target`` the depth of the road
point ``contact_m`` ahead of the chosen rear range (horizontally corrected for the few degrees
the source car is turned, :attr:`CarCutout.face_scale`), and the middle of the contact row lands
on that road point. The truth box of a frame is the pasted outline's own box
(:func:`truth_box`): the hull of what the camera sees, bottom at the tyres. The rear face
itself, 0.2-0.5 m nearer than the plane, is drawn a few per cent small at targets further than
the source; it makes neither the bottom nor the sides of the box there. What the similarity cannot reproduce: the strip of roof that shows above the rear window
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

KITTI material: CC BY-NC-SA 3.0, Geiger, Lenz, Stiller, Urtasun, "Vision meets Robotics: The
KITTI Dataset", IJRR 2013. It is read at run time and never copied into the project.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from vid2sim.base.errors import FormatError, InconsistentInputError, MissingInputError
from vid2sim.base.fileio import read_input_text
from vid2sim.core.camera import Camera, load_camera, parse_kitti_calib
from vid2sim.detect.vehicles.external import KittiLabel, read_kitti_tracking_labels

# A rear view: the car heads within this angle of the camera axis [deg].
MAX_REAR_YAW_DEG = 15.0
MIN_CUTOUT_HEIGHT_PX = 40.0
# Width of the soft edge of the cut-out [source px] (Gaussian sigma of the alpha).
FEATHER_SIGMA_PX = 1.2
# Silhouette prior of a car from behind (fractions of the rear face): the body is full width
# up to the belt line, the cabin above it narrows towards the roof.
_BELT_FRACTION = 0.45  # belt line height above the bottom, as a share of the face height
_ROOF_INSET = 0.13  # inset of the roof corners, as a share of the face width



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
        The point of the crop that lands on the road [crop px] (u, v): the middle of the tyres'
        contact row (or, with ``contact_m`` 0, of the rear face's bottom).
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
    contact_m : float
        Depth of the tyres' contact (the plane the cut-out is drawn on) ahead of the rear face
        [m]; 0 draws the rear face itself (a flat cut-out).
    outline_box_px : tuple, optional
        Box of the cut-out's visible outline (alpha >= 0.5) in crop pixels; None: the rear
        box.
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
    contact_m: float = 0.0
    outline_box_px: tuple[float, float, float, float] | None = None

    @property
    def plane_depth_m(self) -> float:
        """Depth of the plane the cut-out is drawn on in the source camera [m]."""
        return self.depth_m + self.contact_m

    @property
    def visible_width_m(self) -> float:
        """Width of the pasted outline at its plane [m] (narrower than the 3D box: the crop
        keeps the car's rear, not its flank or mirrors)."""
        return ((self.rear_box_px[2] - self.rear_box_px[0]) * self.face_scale
                * self.plane_depth_m / self.focal_px)


def read_kitti_projection(calib_path: Path, cam: int = 2) -> np.ndarray:
    """The 3x4 rectified projection ``P{cam}`` of a KITTI tracking ``calib/SSSS.txt``.

    Labels are in the rectified reference camera (camera 0); ``P2`` carries the offset of the
    colour camera (about 6 cm, several pixels at a few metres), which :func:`load_camera`'s
    pinhole drops.
    """
    values = parse_kitti_calib(read_input_text(Path(calib_path))).get(f"P{cam}")
    if values is None or values.size != 12:
        raise FormatError(calib_path, f"no 3x4 projection P{cam}")
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
                margin_px: int = 6, contact_row_px: float | None = None) -> CarCutout:
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
    contact_row_px : float, optional
        Image row of the rear tyres' contact with the road (the lowest car pixels, read off
        the image); its depth on the label's ground plane sets the plane the cut-out is
        drawn on. None: the rear face's bottom row (a flat cut-out at the rear face).
    margin_px : int
        Background kept around the car in the crop (room for the feathered edge).

    Returns
    -------
    CarCutout
        ``anchor_px`` is the middle of the columns on the contact row (else on the row of
        the rear face's bottom);
        ``face_scale`` corrects the source's slight yaw (a rear face turned by a few degrees
        off a side position looks a few per cent wider than one square to the camera).
    """
    face = _rear_face_in_image(label, yaw_rad, proj, columns_px, contact_row_px)
    fx1, top, fx2, fy2 = face.box_px
    hgt, wid = image_bgr.shape[:2]
    bottom = max(fy2, label.box_px[3]) if contact_row_px is None else fy2
    cx1 = max(math.floor(fx1) - margin_px, 0)
    cy1 = max(math.floor(top) - margin_px, 0)
    cx2 = min(math.ceil(fx2) + margin_px, wid - 1)
    cy2 = min(math.ceil(bottom) + margin_px, hgt - 1)
    alpha = _silhouette_alpha(image_bgr, label.box_px, face)

    gray = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    sl = (slice(cy1, cy2 + 1), slice(cx1, cx2 + 1))
    # Pixel coordinates as the projection gives them (integer = pixel centre), crop-relative.
    anchor = (0.5 * (fx1 + fx2) - cx1, fy2 - cy1)
    ys, xs = np.nonzero(alpha[sl] >= 0.5)
    outline_box = ((float(xs.min()) - 0.5, float(ys.min()) - 0.5, float(xs.max()) + 0.5,
                    float(ys.max()) + 0.5) if xs.size else None)
    h3, w3, l3 = label.size_hwl_m
    return CarCutout(
        gray=np.ascontiguousarray(gray[sl]), alpha=np.ascontiguousarray(alpha[sl]),
        anchor_px=(float(anchor[0]), float(anchor[1])),
        rear_box_px=(fx1 - cx1, top - cy1, fx2 - cx1, fy2 - cy1),
        depth_m=face.depth_m, focal_px=float(proj[0, 0]), width_m=float(w3),
        height_m=float(h3), length_m=float(l3), source=source,
        face_scale=float(face.scale), contact_m=face.contact_m, outline_box_px=outline_box)


@dataclass(frozen=True, slots=True)
class _RearFace:
    """The car's rear as the crop sees it: ``box_px`` (left column, top row, right column,
    bottom row) [px], ``face_top_px`` the projected rear face's top row, ``depth_m`` the face's
    depth, ``scale`` its yaw correction and ``contact_m`` how far ahead of it the tyres touch
    the road (see :class:`CarCutout`)."""

    box_px: tuple[float, float, float, float]
    face_top_px: float
    depth_m: float
    scale: float
    contact_m: float


def _rear_face_in_image(label: KittiLabel, yaw_rad: float, proj: np.ndarray,
                        columns_px: tuple[float, float] | None,
                        contact_row_px: float | None) -> _RearFace:
    """The rear's columns (given, else the projected rear face within the label box), its top
    (the label box's or the face's, whichever is higher) and its bottom: the tyres' contact
    row, on the label's ground plane, else the projected face's bottom."""
    uv, depth, _ = _rear_face(label, yaw_rad, proj)
    bx1, by1, bx2, _ = label.box_px
    fx1, fy1 = float(uv[:, 0].min()), float(uv[:, 1].min())
    fx2, fy2 = float(uv[:, 0].max()), float(uv[:, 1].max())
    face_scale = (proj[0, 0] * label.size_hwl_m[1] / depth) / (fx2 - fx1)
    if columns_px is not None:
        fx1, fx2 = (float(c) for c in columns_px)
    else:
        fx1, fx2 = max(fx1, bx1), min(fx2, bx2)
    contact_m = 0.0
    if contact_row_px is not None:
        # Depth of the contact row on the label's ground plane (y = the box's bottom, in the
        # rectified camera frame): v z = f y + c_y z + P[1, 3].
        y_ground = float(label.location_m[1])
        z_contact = (proj[1, 1] * y_ground + proj[1, 3]) / (contact_row_px - proj[1, 2])
        if not z_contact > depth:
            raise InconsistentInputError(
                None, f"contact row {contact_row_px} px lies nearer than the rear face")
        contact_m = float(z_contact - depth)
        fy2 = float(contact_row_px)
    return _RearFace((fx1, min(by1, fy1), fx2, fy2), fy1, depth, face_scale, contact_m)


def _silhouette_alpha(image_bgr: np.ndarray, label_box: tuple[float, float, float, float],
                      face: _RearFace) -> np.ndarray:
    """(H, W) float32 opacity of the car in the whole frame: GrabCut's foreground in the label
    box intersected with the rear-outline prior, the body below the belt line filled, opened
    and closed, cut to the rear's columns and bottom, feathered."""
    bx1, by1, bx2, by2 = label_box
    fx1, top, fx2, fy2 = face.box_px
    hgt, wid = image_bgr.shape[:2]
    # GrabCut on the frame with the label box as the foreground rectangle.
    rect = (int(bx1), int(by1), math.ceil(bx2 - bx1), math.ceil(by2 - by1))
    gc_mask = np.zeros((hgt, wid), np.uint8)
    bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
    cv2.setRNGSeed(0)
    cv2.grabCut(image_bgr, gc_mask, rect, bgd, fgd, 5, cv2.GC_INIT_WITH_RECT)
    fg = np.where((gc_mask == cv2.GC_FGD) | (gc_mask == cv2.GC_PR_FGD), 255, 0).astype(np.uint8)
    prior = _silhouette_prior((hgt, wid), (fx1, face.face_top_px, fx2, fy2), top)
    mask = cv2.bitwise_and(fg, prior)
    # The body below the belt line is solid: fill GrabCut's holes (dark bumper, plate).
    belt = round(fy2 - _BELT_FRACTION * (fy2 - top))
    body = np.zeros_like(mask)
    body[belt:math.ceil(fy2) + 1] = prior[belt:math.ceil(fy2) + 1]
    mask = cv2.bitwise_or(mask, body)
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    mask = cv2.morphologyEx(cv2.morphologyEx(mask, cv2.MORPH_OPEN, k), cv2.MORPH_CLOSE, k)
    # Nothing outside the rear columns or below the bottom (the tyres' contact, or the rear
    # face's bottom on the road).
    cols = np.arange(wid)[None, :]
    rows = np.arange(hgt)[:, None]
    inside = (cols >= fx1) & (cols <= fx2) & (rows <= fy2)
    mask = np.where(inside, mask, 0).astype(np.float32) / 255.0
    return cv2.GaussianBlur(mask, (0, 0), FEATHER_SIGMA_PX)


# The cars at hand: name -> (sequence, frame, track id, columns of the rear outline or None,
# row of the tyres' contact or None). "polo" is a small hatchback (a VW Polo 6N) parked 6.6 m
# ahead on the right (rear 164 x 156 px), the only labelled car of the frames at hand seen from
# behind, whole and unoccluded at a useful size. Its columns are read off the image: the
# label's projected rear face reaches 15 px past the car's right side (a wall there) and starts
# 8 px inside the left tail light. Its lowest pixels, the left rear tyre on the pavement, end on
# row 332 (the right one on 324; the bumper's edge is on row 310, the label's rear face meets
# the ground on rows 335-338). On the label's ground plane that row lies 0.19 m ahead of the
# label's rear face; the label's box is 3.16 m long where a Polo 6N is 3.74 m, so its rear
# face may sit up to 0.3 m inside the bumper, and the truth of a composite is the label's.
# The other candidates fail: 0001/20 object 5 stands behind a post, 0016/2 objects 1 and 2
# behind a railing, and 0016/2 object 3 (a dark car 35 m ahead, 30 px high) is too small for
# GrabCut to find its outline and would be upscaled at any nearer range.
CARS: dict[str, tuple[str, int, int, tuple[float, float] | None, float | None]] = {
    "polo": ("0001", 10, 2, (838.0, 1002.0), 332.0),
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
    seq, frame, track, columns, contact_row = CARS[car]
    tracking_dir = Path(tracking_dir)
    img_path = tracking_dir / "image_02" / seq / f"{frame:06d}.png"
    image = cv2.imread(str(img_path), cv2.IMREAD_COLOR)
    if image is None:
        raise MissingInputError(img_path, "cannot read this KITTI frame")
    label_path = tracking_dir / "label_02" / f"{seq}.txt"
    found = [(lb, yaw) for lb, yaw in read_labels_with_yaw(label_path).get(frame, [])
             if lb.track_id == track]
    if not found:
        raise MissingInputError(label_path, f"no object {track} in frame {frame}")
    label, yaw = found[0]
    if require_rear_view and not is_rear_view(label, yaw):
        raise InconsistentInputError(
            img_path, f"object {track} is not a whole car seen from behind")
    calib = tracking_dir / "calib" / f"{seq}.txt"
    proj = read_kitti_projection(calib)
    if abs(load_camera(calib).fx - proj[0, 0]) > 1e-6:  # the same calibration, read twice
        raise InconsistentInputError(calib, "P2 and the camera disagree on the focal length")
    return cut_out_car(image, label, yaw, proj, columns_px=columns, contact_row_px=contact_row,
                       source=f"kitti_tracking {seq}/{frame:06d} object {track} ({car})")


# --------------------------------------------------------------------------- the paste


def paste_transform(cutout: CarCutout, camera: Camera, range_m: float, lateral_m: float
                    ) -> np.ndarray:
    """The 2x3 affine map from crop pixels to target pixels for a car at (``range_m``,
    ``lateral_m``): ``range_m`` is the vehicle-frame x of its rear, ``lateral_m`` the y of its
    centre.

    Scale ``(f_t / f_s) * (Z_c / z_t)`` (horizontally times ``face_scale``) with ``Z_c`` the
    source depth of the cut-out's plane (the tyres' contact) and ``z_t`` the target depth of
    the road point ``contact_m`` ahead of the rear; shift so the crop's anchor lands on that
    point's projection.
    """
    ground = np.array([[range_m + cutout.contact_m, lateral_m, 0.0]])
    uv, ok = camera.project(ground)
    if not ok.all():
        raise ValueError(f"a car at range {range_m} m is not in front of the camera")
    depth = float(camera.vehicle_to_camera(ground)[0, 2])
    sy = (camera.fy / cutout.focal_px) * (cutout.plane_depth_m / depth)
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


def truth_box(cutout: CarCutout, camera: Camera, range_m: float, lateral_m: float
              ) -> tuple[float, float, float, float] | None:
    """The box of the pasted outline at (``range_m``, ``lateral_m``) [px], clipped to the image:
    the cut-out's visible outline (alpha >= 0.5) mapped by :func:`paste_transform`. What a
    camera sees of this car: its bottom the tyres' contact, its sides the body; None where the
    car lies outside the image."""
    m = paste_transform(cutout, camera, range_m, lateral_m)
    x1, y1, x2, y2 = cutout.outline_box_px or cutout.rear_box_px
    u1, v1 = m[0, 0] * x1 + m[0, 2], m[1, 1] * y1 + m[1, 2]
    u2, v2 = m[0, 0] * x2 + m[0, 2], m[1, 1] * y2 + m[1, 2]
    w, h = camera.image_width - 1, camera.image_height - 1
    if u2 < 0 or v2 < 0 or u1 > w or v1 > h:
        return None
    return (float(np.clip(u1, 0, w)), float(np.clip(v1, 0, h)), float(np.clip(u2, 0, w)),
            float(np.clip(v2, 0, h)))
