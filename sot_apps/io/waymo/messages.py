"""The subset of Waymo Open Dataset v1 messages this reader needs, defined in Python.

Field numbers and types follow the format's documentation (``waymo.open_dataset`` Frame, Context,
CameraCalibration, LaserCalibration, CameraImage, Laser, RangeImage, MatrixFloat, Label). Enums are
read as plain integers; fields not listed here are kept as unknown fields and ignored. The message
classes are built from a ``FileDescriptorProto`` with the ``protobuf`` package (no .proto file, no
generated code).
"""

from __future__ import annotations

from functools import lru_cache
from types import SimpleNamespace

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

__all__ = ["messages", "LABEL_TYPES", "LASER_NAMES", "CAMERA_NAMES"]

_PACKAGE = "sot_apps.waymo_v1"
F = descriptor_pb2.FieldDescriptorProto

# (name, number, type, label, message type name or None)
_OPT, _REP = F.LABEL_OPTIONAL, F.LABEL_REPEATED
_MESSAGES: dict[str, list[tuple[str, int, int, int, str | None]]] = {
    "MatrixShape": [("dims", 1, F.TYPE_INT32, _REP, None)],
    "MatrixFloat": [("data", 1, F.TYPE_FLOAT, _REP, None), ("shape", 2, F.TYPE_MESSAGE, _OPT, "MatrixShape")],
    "Transform": [("transform", 1, F.TYPE_DOUBLE, _REP, None)],
    "CameraCalibration": [
        ("name", 1, F.TYPE_INT32, _OPT, None), ("intrinsic", 2, F.TYPE_DOUBLE, _REP, None),
        ("extrinsic", 3, F.TYPE_MESSAGE, _OPT, "Transform"), ("width", 4, F.TYPE_INT32, _OPT, None),
        ("height", 5, F.TYPE_INT32, _OPT, None), ("rolling_shutter_direction", 6, F.TYPE_INT32, _OPT, None)],
    "LaserCalibration": [
        ("name", 1, F.TYPE_INT32, _OPT, None), ("beam_inclinations", 2, F.TYPE_DOUBLE, _REP, None),
        ("beam_inclination_min", 3, F.TYPE_DOUBLE, _OPT, None), ("beam_inclination_max", 4, F.TYPE_DOUBLE, _OPT, None),
        ("extrinsic", 5, F.TYPE_MESSAGE, _OPT, "Transform")],
    "Context": [
        ("name", 1, F.TYPE_STRING, _OPT, None),
        ("camera_calibrations", 2, F.TYPE_MESSAGE, _REP, "CameraCalibration"),
        ("laser_calibrations", 3, F.TYPE_MESSAGE, _REP, "LaserCalibration")],
    "RangeImage": [
        ("range_image_compressed", 2, F.TYPE_BYTES, _OPT, None),
        ("range_image_pose_compressed", 4, F.TYPE_BYTES, _OPT, None)],
    "Laser": [("name", 1, F.TYPE_INT32, _OPT, None), ("ri_return1", 2, F.TYPE_MESSAGE, _OPT, "RangeImage"),
              ("ri_return2", 3, F.TYPE_MESSAGE, _OPT, "RangeImage")],
    "CameraImage": [
        ("name", 1, F.TYPE_INT32, _OPT, None), ("image", 2, F.TYPE_BYTES, _OPT, None),
        ("pose", 3, F.TYPE_MESSAGE, _OPT, "Transform"), ("pose_timestamp", 5, F.TYPE_DOUBLE, _OPT, None),
        ("shutter", 6, F.TYPE_DOUBLE, _OPT, None), ("camera_trigger_time", 7, F.TYPE_DOUBLE, _OPT, None),
        ("camera_readout_done_time", 8, F.TYPE_DOUBLE, _OPT, None)],
    "Box": [
        ("center_x", 1, F.TYPE_DOUBLE, _OPT, None), ("center_y", 2, F.TYPE_DOUBLE, _OPT, None),
        ("center_z", 3, F.TYPE_DOUBLE, _OPT, None), ("width", 4, F.TYPE_DOUBLE, _OPT, None),
        ("length", 5, F.TYPE_DOUBLE, _OPT, None), ("height", 6, F.TYPE_DOUBLE, _OPT, None),
        ("heading", 7, F.TYPE_DOUBLE, _OPT, None)],
    "Label": [
        ("box", 1, F.TYPE_MESSAGE, _OPT, "Box"), ("type", 3, F.TYPE_INT32, _OPT, None),
        ("id", 4, F.TYPE_STRING, _OPT, None), ("detection_difficulty_level", 5, F.TYPE_INT32, _OPT, None),
        ("tracking_difficulty_level", 6, F.TYPE_INT32, _OPT, None),
        ("num_lidar_points_in_box", 7, F.TYPE_INT32, _OPT, None),
        ("num_top_lidar_points_in_box", 13, F.TYPE_INT32, _OPT, None)],
    "CameraLabels": [("name", 1, F.TYPE_INT32, _OPT, None), ("labels", 2, F.TYPE_MESSAGE, _REP, "Label")],
    # Frame without its heavy repeated fields (images = 4, lasers = 5): the reader locates those itself.
    "FrameHeader": [
        ("context", 1, F.TYPE_MESSAGE, _OPT, "Context"), ("timestamp_micros", 2, F.TYPE_INT64, _OPT, None),
        ("pose", 3, F.TYPE_MESSAGE, _OPT, "Transform"), ("laser_labels", 6, F.TYPE_MESSAGE, _REP, "Label"),
        ("projected_lidar_labels", 9, F.TYPE_MESSAGE, _REP, "CameraLabels")],
}

# Frame field numbers of the repeated sensor data located without decoding.
FRAME_IMAGES = 4
FRAME_LASERS = 5
CAMERA_IMAGE_BYTES = 2

LABEL_TYPES = {0: "Unknown", 1: "Vehicle", 2: "Pedestrian", 3: "Sign", 4: "Cyclist"}
LASER_NAMES = {0: "UNKNOWN", 1: "TOP", 2: "FRONT", 3: "SIDE_LEFT", 4: "SIDE_RIGHT", 5: "REAR"}
CAMERA_NAMES = {0: "UNKNOWN", 1: "FRONT", 2: "FRONT_LEFT", 3: "FRONT_RIGHT", 4: "SIDE_LEFT", 5: "SIDE_RIGHT",
                6: "REAR_LEFT", 7: "REAR", 8: "REAR_RIGHT"}


@lru_cache(maxsize=1)
def messages() -> SimpleNamespace:
    """Message classes by name (``messages().Label``, ...)."""
    file_proto = descriptor_pb2.FileDescriptorProto(name="sot_apps_waymo_v1.proto", package=_PACKAGE, syntax="proto2")
    for name, fields in _MESSAGES.items():
        message = file_proto.message_type.add(name=name)
        for field_name, number, ftype, label, type_name in fields:
            field = message.field.add(name=field_name, number=number, type=ftype, label=label)
            if type_name:
                field.type_name = f".{_PACKAGE}.{type_name}"
            if ftype in (F.TYPE_FLOAT, F.TYPE_INT32, F.TYPE_DOUBLE) and label == _REP:
                field.options.packed = field_name == "data"  # MatrixFloat.data is declared packed; parsers accept both
    pool = descriptor_pool.DescriptorPool()
    pool.Add(file_proto)
    return SimpleNamespace(**{name: message_factory.GetMessageClass(pool.FindMessageTypeByName(f"{_PACKAGE}.{name}"))
                              for name in _MESSAGES})
