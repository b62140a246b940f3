"""
The CDR bytes of a ``visualization_msgs/msg/MarkerArray`` (ROS 2 Jazzy), from numpy arrays.

A roadmap's markers hold tens of thousands of points: building a ``geometry_msgs/Point`` for
each and letting rclpy convert them is slow, while the points of a marker are one block
of float64 triples in the message. ``Marker`` holds a marker's fields with its points,
colours and texture coordinates as arrays, and ``marker_array`` writes the bytes
(``Publisher.publish`` takes them as they are; the recorder records the same bytes) with
the trajectories' ``Writer``. Jazzy's ``Marker``, field by field::

    std_msgs/Header header          int32 sec, uint32 nanosec, string frame_id
    string ns
    int32 id, int32 type, int32 action
    geometry_msgs/Pose pose         float64 x, y, z; float64 x, y, z, w
    geometry_msgs/Vector3 scale     float64 x, y, z
    std_msgs/ColorRGBA color        float32 r, g, b, a
    builtin_interfaces/Duration lifetime
    bool frame_locked
    geometry_msgs/Point[] points
    std_msgs/ColorRGBA[] colors
    string texture_resource
    sensor_msgs/CompressedImage texture     header, string format, uint8[] data
    visualization_msgs/UVCoordinate[] uv_coordinates   float32 u, v
    string text
    string mesh_resource
    visualization_msgs/MeshFile mesh_file   string filename, uint8[] data
    bool mesh_use_embedded_materials
"""

from dataclasses import dataclass, field
import enum
from typing import Sequence, Tuple

import numpy as np

from wafer_planner_ros.service.cdr import Writer


class Shape(enum.IntEnum):
    """A marker's ``type``."""

    ARROW = 0
    CUBE = 1
    SPHERE = 2
    CYLINDER = 3
    LINE_STRIP = 4
    LINE_LIST = 5
    CUBE_LIST = 6
    SPHERE_LIST = 7
    POINTS = 8
    TEXT_VIEW_FACING = 9
    MESH_RESOURCE = 10
    TRIANGLE_LIST = 11
    ARROW_STRIP = 12


class Action(enum.IntEnum):
    """A marker's ``action``."""

    ADD = 0
    DELETE = 2
    DELETEALL = 3
    """Delete every marker of the display (of the namespace, when ``ns`` is given)."""


@dataclass(frozen=True)
class CompressedImage:
    """A ``sensor_msgs/msg/CompressedImage`` (a marker's texture)."""

    stamp: Tuple[int, int] = (0, 0)
    """(sec, nanosec)."""
    frame_id: str = ''
    format: str = ''  # noqa: A003 - the message's field name
    data: bytes = b''


@dataclass(frozen=True)
class MeshFile:
    """A ``visualization_msgs/msg/MeshFile``: a mesh given inline."""

    filename: str = ''
    data: bytes = b''


def _rows(width: int):
    return field(default_factory=lambda: np.empty((0, width)))


@dataclass(frozen=True, eq=False)
class Marker:
    """One ``visualization_msgs/msg/Marker``; the defaults are the message's."""

    frame_id: str = ''
    stamp: Tuple[int, int] = (0, 0)
    """(sec, nanosec) of the header."""
    ns: str = ''
    id: int = 0  # noqa: A003 - the message's field name
    type: Shape = Shape.ARROW  # noqa: A003 - the message's field name
    action: Action = Action.ADD
    position: Sequence[float] = (0.0, 0.0, 0.0)
    """m, in ``frame_id``."""
    orientation: Sequence[float] = (0.0, 0.0, 0.0, 1.0)
    """Quaternion x, y, z, w."""
    scale: Sequence[float] = (0.0, 0.0, 0.0)
    color: Sequence[float] = (0.0, 0.0, 0.0, 0.0)
    """r, g, b, a in [0, 1]."""
    lifetime: Tuple[int, int] = (0, 0)
    """(sec, nanosec); 0: for ever."""
    frame_locked: bool = False
    points: np.ndarray = _rows(3)
    """(N, 3) m."""
    colors: np.ndarray = _rows(4)
    """(N, 4) one colour per point, or (0, 4): ``color`` for all."""
    texture_resource: str = ''
    texture: CompressedImage = CompressedImage()
    uv_coordinates: np.ndarray = _rows(2)
    """(N, 2) u, v per point."""
    text: str = ''
    mesh_resource: str = ''
    mesh_file: MeshFile = MeshFile()
    mesh_use_embedded_materials: bool = False


def marker_array(markers: Sequence[Marker]) -> bytes:
    """Return the serialised ``visualization_msgs/msg/MarkerArray`` of ``markers``."""
    writer = Writer()
    writer.uint32(len(markers))
    for marker in markers:
        _write(writer, marker)
    return writer.serialised()


def _write(writer: Writer, marker: Marker) -> None:
    def table(name: str, width: int) -> np.ndarray:
        rows = np.asarray(getattr(marker, name), float)
        if rows.size == 0:
            return np.empty((0, width))
        if rows.ndim != 2 or rows.shape[1] != width:
            raise ValueError(f'marker {marker.ns!r} {marker.id}: {name} must have shape '
                             f'(N, {width}), got {rows.shape}')
        return rows

    def vector(name: str, size: int):
        values = np.asarray(getattr(marker, name), float).reshape(-1)
        if len(values) != size:
            raise ValueError(f'marker {marker.ns!r} {marker.id}: {name} must have {size} '
                             f'values, got {len(values)}')
        return values

    writer.header(*marker.stamp, marker.frame_id)
    writer.string(marker.ns)
    writer.int32(marker.id)
    writer.int32(int(marker.type))
    writer.int32(int(marker.action))
    writer.fixed(vector('position', 3), '<f8')
    writer.fixed(vector('orientation', 4), '<f8')
    writer.fixed(vector('scale', 3), '<f8')
    writer.fixed(vector('color', 4), '<f4')
    writer.int32(marker.lifetime[0])
    writer.uint32(marker.lifetime[1])
    writer.boolean(marker.frame_locked)
    writer.sequence(table('points', 3), '<f8')
    writer.sequence(table('colors', 4), '<f4')
    writer.string(marker.texture_resource)
    writer.header(*marker.texture.stamp, marker.texture.frame_id)
    writer.string(marker.texture.format)
    writer.sequence(np.frombuffer(marker.texture.data, np.uint8), '<u1')
    writer.sequence(table('uv_coordinates', 2), '<f4')
    writer.string(marker.text)
    writer.string(marker.mesh_resource)
    writer.string(marker.mesh_file.filename)
    writer.sequence(np.frombuffer(marker.mesh_file.data, np.uint8), '<u1')
    writer.boolean(marker.mesh_use_embedded_materials)
