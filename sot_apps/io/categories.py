"""Object categories of the label formats the toolkit writes (KITTI tracking types, Argoverse 2 categories).

A sequence's labels are the source dataset's own names (KITTI ``Car``, AV2 ``REGULAR_VEHICLE``, nuScenes
``vehicle.car``, Waymo ``Vehicle``, PandaSet ``Pickup Truck``, ...). :func:`kitti_type` and
:func:`av2_category` map one to the target format's name, or None when the format has no such category
(the writers leave those boxes out and say how many). Matching ignores case, spaces, ``-`` and ``_``.
"""

from __future__ import annotations

import re

__all__ = ["KITTI_TYPES", "AV2_CATEGORIES", "kitti_type", "av2_category"]

KITTI_TYPES = ("Car", "Van", "Truck", "Pedestrian", "Person_sitting", "Cyclist", "Tram", "Misc")

# the 30 categories of the AV2 sensor dataset (av2.datasets.sensor.constants.AnnotationCategories)
AV2_CATEGORIES = (
    "ANIMAL", "ARTICULATED_BUS", "BICYCLE", "BICYCLIST", "BOLLARD", "BOX_TRUCK", "BUS", "CONSTRUCTION_BARREL",
    "CONSTRUCTION_CONE", "DOG", "LARGE_VEHICLE", "MESSAGE_BOARD_TRAILER", "MOBILE_PEDESTRIAN_CROSSING_SIGN",
    "MOTORCYCLE", "MOTORCYCLIST", "OFFICIAL_SIGNALER", "PEDESTRIAN", "RAILED_VEHICLE", "REGULAR_VEHICLE",
    "SCHOOL_BUS", "SIGN", "STOP_SIGN", "STROLLER", "TRAFFIC_LIGHT_TRAILER", "TRUCK", "TRUCK_CAB",
    "VEHICULAR_TRAILER", "WHEELCHAIR", "WHEELED_DEVICE", "WHEELED_RIDER",
)


def _key(label: str) -> str:
    return re.sub(r"[\s_\-]+", "", label).lower()


# other datasets' names (normalised with _key) -> AV2 category
_TO_AV2 = {_key(k): v for k, v in {
    # KITTI
    "Car": "REGULAR_VEHICLE", "Van": "REGULAR_VEHICLE", "Truck": "TRUCK", "Pedestrian": "PEDESTRIAN",
    "Person_sitting": "PEDESTRIAN", "Cyclist": "BICYCLIST", "Tram": "RAILED_VEHICLE",
    # Waymo
    "Vehicle": "REGULAR_VEHICLE", "Sign": "SIGN",
    # nuScenes
    "vehicle.car": "REGULAR_VEHICLE", "vehicle.truck": "TRUCK", "vehicle.bus.bendy": "ARTICULATED_BUS",
    "vehicle.bus.rigid": "BUS", "vehicle.trailer": "VEHICULAR_TRAILER", "vehicle.construction": "LARGE_VEHICLE",
    "vehicle.emergency.police": "REGULAR_VEHICLE", "vehicle.emergency.ambulance": "LARGE_VEHICLE",
    "vehicle.motorcycle": "MOTORCYCLE", "vehicle.bicycle": "BICYCLE",
    "human.pedestrian.adult": "PEDESTRIAN", "human.pedestrian.child": "PEDESTRIAN",
    "human.pedestrian.construction_worker": "PEDESTRIAN", "human.pedestrian.police_officer": "OFFICIAL_SIGNALER",
    "human.pedestrian.stroller": "STROLLER", "human.pedestrian.wheelchair": "WHEELCHAIR",
    "human.pedestrian.personal_mobility": "WHEELED_RIDER", "movable_object.trafficcone": "CONSTRUCTION_CONE",
    "movable_object.barrier": "CONSTRUCTION_BARREL", "animal": "ANIMAL",
    # PandaSet
    "Pickup Truck": "REGULAR_VEHICLE", "Medium-sized Truck": "BOX_TRUCK", "Semi-truck": "TRUCK_CAB",
    "Towed Object": "VEHICULAR_TRAILER", "Motorcycle": "MOTORCYCLE", "Bicycle": "BICYCLE", "Bus": "BUS",
    "Emergency Vehicle": "LARGE_VEHICLE", "Other Vehicle - Construction Vehicle": "LARGE_VEHICLE",
    "Other Vehicle - Uncommon": "LARGE_VEHICLE", "Other Vehicle - Pedicab": "WHEELED_RIDER",
    "Personal Mobility Device": "WHEELED_DEVICE", "Motorized Scooter": "WHEELED_DEVICE",
    "Train": "RAILED_VEHICLE", "Trolley": "RAILED_VEHICLE", "Tram / Subway": "RAILED_VEHICLE",
    "Pedestrian with Object": "PEDESTRIAN", "Animals - Other": "ANIMAL", "Cones": "CONSTRUCTION_CONE",
    "Signs": "SIGN", "Construction Signs": "SIGN",
}.items()}
_TO_AV2.update({_key(c): c for c in AV2_CATEGORIES})

_AV2_TO_KITTI = {
    "REGULAR_VEHICLE": "Car", "LARGE_VEHICLE": "Truck", "BOX_TRUCK": "Truck", "TRUCK": "Truck", "TRUCK_CAB": "Truck",
    "BUS": "Misc", "SCHOOL_BUS": "Misc", "ARTICULATED_BUS": "Misc", "VEHICULAR_TRAILER": "Misc",
    "PEDESTRIAN": "Pedestrian", "OFFICIAL_SIGNALER": "Pedestrian", "BICYCLIST": "Cyclist", "MOTORCYCLIST": "Cyclist",
    "RAILED_VEHICLE": "Tram",
}
# names whose KITTI type is not their AV2 category's (a van is a KITTI Van, a pickup a KITTI Car, ...)
_TO_KITTI = {_key(k): v for k, v in {
    "Van": "Van", "Person_sitting": "Person_sitting", "Misc": "Misc", "Pickup Truck": "Car",
    "vehicle.emergency.police": "Car",
}.items()}
_TO_KITTI.update({_key(t): t for t in KITTI_TYPES})


def av2_category(label: str) -> str | None:
    """The AV2 category of a dataset label (``Car`` -> ``REGULAR_VEHICLE``), or None."""
    return _TO_AV2.get(_key(label))


def kitti_type(label: str) -> str | None:
    """The KITTI tracking type of a dataset label (``REGULAR_VEHICLE`` -> ``Car``), or None."""
    key = _key(label)
    if key in _TO_KITTI:
        return _TO_KITTI[key]
    category = _TO_AV2.get(key)
    return None if category is None else _AV2_TO_KITTI.get(category)
