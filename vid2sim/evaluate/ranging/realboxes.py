"""Real detector boxes against lidar truth: join ranged detections with annotated vehicles.

The caller runs the detector and the ranging on an image; these functions find which
annotated vehicle each ranged box is (one-to-one by IoU with the annotation's 2D box, which is
only used for the association) and attach the truth from the annotation's 3D box: the range
of its nearest end in the camera's vehicle frame and the lateral offset of its centre. The
truth is never the 2D box itself: a KITTI label's 2D box is the projected cuboid (94 % within
1.5 px), not what a detector sees.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vid2sim.base.fileio import read_input_text
from vid2sim.core.camera import Camera
from vid2sim.core.records import RangedBox, VehicleCategory
from vid2sim.detect.vehicles.external import KittiLabel
from vid2sim.evaluate.metrics import match_boxes
from vid2sim.evaluate.ranging.dgp import DgpFrame, cuboid_range_m

#: DGP classes scored as vehicles and what a COCO detector calls them.
DGP_VEHICLES = {"Car": VehicleCategory.CAR, "Truck": VehicleCategory.TRUCK,
                "Bus/RV/Caravan": VehicleCategory.BUS}
#: KITTI tracking classes scored as vehicles (COCO has no van: a van is a "car").
KITTI_VEHICLES = {"Car": VehicleCategory.CAR, "Van": VehicleCategory.CAR,
                  "Truck": VehicleCategory.TRUCK}
#: A ranged box is the annotated vehicle whose 2D box it overlaps by at least this.
MATCH_IOU = 0.5


@dataclass(frozen=True)
class RealBoxRow:
    """One ranged detector box matched to an annotated vehicle.

    ``truth_m``: range of the vehicle's nearest end [m]; ``truth_lateral_m``: its centre's
    lateral offset (left positive) [m]; ``range_m`` / ``lateral_m``: the estimates;
    ``iou``: of the detector box with the annotation's 2D box; ``box_px``: the detector box.
    """

    source: str
    category: str
    truth_m: float
    range_m: float
    truth_lateral_m: float
    lateral_m: float
    iou: float
    box_px: tuple[float, float, float, float]


def _pairs(ranged: Sequence[RangedBox], annotated: Sequence[tuple[float, float, float, float]]
           ) -> list[tuple[int, int, float]]:
    det = np.array([(b.x1, b.y1, b.x2, b.y2) for b in ranged], dtype=float).reshape(-1, 4)
    ann = np.asarray(annotated, dtype=float).reshape(-1, 4)
    return match_boxes(det, ann, min_iou=MATCH_IOU)


def dgp_rows(frame: DgpFrame, camera: Camera, ranged: Sequence[RangedBox]) -> list[RealBoxRow]:
    """Rows of one DGP frame: each ranged box matched to a 2D box of a vehicle whose 3D box
    (same ``instance_id``) gives the truth in ``camera``'s vehicle frame."""
    cuboids = {c.instance_id: c for c in frame.cuboids if c.class_name in DGP_VEHICLES}
    boxes = [b for b in frame.boxes_2d if b.instance_id in cuboids]
    rows = []
    for i, j, iou in _pairs(ranged, [b.box_px for b in boxes]):
        cub = cuboids[boxes[j].instance_id]
        truth, lat = cuboid_range_m(cub, camera)
        r = ranged[i]
        rows.append(RealBoxRow(f"{frame.scene}/{frame.image.stem}", DGP_VEHICLES[cub.class_name],
                               truth, r.range_m, lat, r.lateral_m, iou,
                               (r.x1, r.y1, r.x2, r.y2)))
    return rows


def read_rotation_y(label_path: Path) -> dict[tuple[int, int], float]:
    """``rotation_y`` [rad] of every object of a KITTI tracking label file, by (frame, track
    id): the heading about the camera's y axis (-pi/2 drives straight away)."""
    out: dict[tuple[int, int], float] = {}
    for line in read_input_text(Path(label_path)).splitlines():
        f = line.split()
        if len(f) >= 17:
            out[(int(f[0]), int(f[1]))] = float(f[16])
    return out


def kitti_corners_m(label: KittiLabel, rotation_y: float) -> np.ndarray:
    """(8, 3) corners of a KITTI label's 3D box in its rectified camera frame (x right, y
    down, z forward) [m]; the location is the box's bottom centre."""
    h, w, length = label.size_hwl_m
    local = np.array([[sx * length / 2, sy, sz * w / 2]
                      for sx in (-1, 1) for sy in (0.0, -h) for sz in (-1, 1)])
    c, s = math.cos(rotation_y), math.sin(rotation_y)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return local @ rot.T + np.asarray(label.location_m, dtype=float)


def kitti_rows(source: str, labels: Sequence[KittiLabel], rotation_y: dict[tuple[int, int], float],
               camera: Camera, ranged: Sequence[RangedBox]) -> list[RealBoxRow]:
    """Rows of one KITTI frame: ranged boxes matched to the labelled vehicles' 2D boxes; the
    truth is the labelled 3D box's nearest end (and centre) in ``camera``'s vehicle frame."""
    objs = [lb for lb in labels if lb.type in KITTI_VEHICLES]
    rows = []
    r_veh = camera.R_veh_from_cam
    for i, j, iou in _pairs(ranged, [lb.box_px for lb in objs]):
        lb = objs[j]
        yaw = rotation_y.get((lb.frame, lb.track_id), -math.pi / 2)
        corners = kitti_corners_m(lb, yaw) @ r_veh.T + camera.position_veh_m
        r = ranged[i]
        rows.append(RealBoxRow(source, KITTI_VEHICLES[lb.type], float(corners[:, 0].min()),
                               r.range_m, float(corners[:, 1].mean()), r.lateral_m, iou,
                               (r.x1, r.y1, r.x2, r.y2)))
    return rows
