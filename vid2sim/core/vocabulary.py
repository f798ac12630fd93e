"""The kinds of things the stages name: vehicle categories (more enums join as they move out
of strings). Each is a ``StrEnum``: it prints, compares and serialises as its value."""

from __future__ import annotations

from enum import StrEnum


class VehicleCategory(StrEnum):
    """What kind of vehicle a box, track or actor is: the categories a detector or an importer
    produces (COCO's car, motorcycle, bus, truck and train; other tools' names are mapped onto
    these, :mod:`vid2sim.detect.vehicles.external`). A ``StrEnum``: it prints, compares and
    serialises as its value (``"car"``)."""

    CAR = "car"
    TRUCK = "truck"
    BUS = "bus"
    MOTORCYCLE = "motorcycle"
    #: rail vehicles (COCO's "train", KITTI's "Tram"); one on its own track bed is never the
    #: ego's lead
    TRAM = "tram"


VEHICLE_CATEGORIES = tuple(VehicleCategory)
#: Vehicles that run on rails: a tram on its own track bed is never the ego's lead.
RAIL_CATEGORIES = (VehicleCategory.TRAM,)
