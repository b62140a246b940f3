"""
RViz/Foxglove markers of the cell, the roadmap and the latest plan (SPEC section 5).

The enclosure, obstacles, stations and wafer trace are drawn in the cell's plane (z = 0).
The roadmap and the joint-space path live in joint space: they are drawn in a cube beside
the cell, each joint's range mapped onto one side (q1 -> x, q2 -> y, q3 -> z).
"""

from geometry_msgs.msg import Point
import numpy as np
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

OUTLINES = 12
"""Robot outlines drawn along a plan."""


def roadmap_markers(cell, roadmap, frame_id: str, stamp) -> MarkerArray:
    """Return the enclosure, obstacles, stations and the roadmap in joint space."""
    markers = [_strip('enclosure', 0, _closed(cell.boundary), (0.8, 0.8, 0.8, 1.0), 0.01)]
    for k, polygon in enumerate(cell.obstacles):
        markers.append(_strip('obstacles', k, _closed(polygon), (0.9, 0.4, 0.1, 1.0), 0.01))
    arm = cell.robot.arm
    k = 0
    for name, station in sorted(cell.stations.items()):
        for config in station.configs:
            markers.append(_strip('stations', k, arm.joint_points(config.q),
                                  (0.2, 0.6, 1.0, 1.0), 0.02))
            label = _marker('station_labels', k, Marker.TEXT_VIEW_FACING, (1.0, 1.0, 1.0, 1.0))
            label.text = name if len(station.configs) == 1 else f'{name} ({config.elbow:+d})'
            label.pose.position = _point(arm.wafer_center(config.q))
            label.scale.z = 0.05
            markers.append(label)
            k += 1
    box = _JointBox(cell)
    nodes = _marker('roadmap_nodes', 0, Marker.POINTS, (0.3, 0.9, 0.3, 1.0))
    nodes.points = _points(box.place(roadmap.nodes))
    nodes.scale.x = nodes.scale.y = 0.008
    edges = _marker('roadmap_edges', 0, Marker.LINE_LIST, (0.3, 0.9, 0.3, 0.15))
    edges.points = _points(box.place(roadmap.nodes[roadmap.edges.reshape(-1)]))
    edges.scale.x = 0.001
    markers += [nodes, edges, _strip('joint_box', 0, box.outline(), (0.5, 0.5, 0.5, 1.0), 0.003,
                                     Marker.LINE_LIST)]
    return _array(markers, frame_id, stamp)


def path_markers(cell, result, frame_id: str, stamp) -> MarkerArray:
    """Return the latest plan: joint-space path, wafer-centre trace, robot outlines."""
    arm, trajectory = cell.robot.arm, result.trajectory
    q = trajectory.evaluate(np.linspace(0.0, trajectory.duration, 400))
    markers = [
        _strip('path_joint_space', 0, _JointBox(cell).place(q), (1.0, 0.9, 0.2, 1.0), 0.006),
        _strip('wafer_trace', 0, arm.wafer_center(q), (1.0, 0.9, 0.2, 1.0), 0.006),
    ]
    outline = _marker('robot', 0, Marker.LINE_LIST, (0.9, 0.9, 0.9, 0.6))
    joints = arm.joint_points(trajectory.evaluate(np.linspace(0.0, trajectory.duration,
                                                              OUTLINES)))
    segments = np.stack([joints[:, :-1], joints[:, 1:]], axis=2).reshape(-1, 2)
    outline.points = _points(segments)
    outline.scale.x = 0.01
    return _array(markers + [outline], frame_id, stamp)


class _JointBox:
    """A cube beside the cell onto which joint space is mapped."""

    def __init__(self, cell):
        low, high = cell.boundary.min(axis=0), cell.boundary.max(axis=0)
        self.size = float(high[1] - low[1])
        self.origin = np.array([high[0] + 0.2 * self.size, low[1], 0.0])
        self.lower, self.upper = cell.robot.limits.position.T

    def place(self, q: np.ndarray) -> np.ndarray:
        return self.origin + (q - self.lower) / (self.upper - self.lower) * self.size

    def outline(self) -> np.ndarray:
        corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
        pairs = [(a, b) for a in range(8) for b in range(a + 1, 8)
                 if np.sum(np.abs(corners[a] - corners[b])) == 1]
        return self.origin + corners[np.array(pairs).reshape(-1)] * self.size


def _marker(ns: str, marker_id: int, kind: int, rgba) -> Marker:
    marker = Marker(ns=ns, id=marker_id, type=kind, action=Marker.ADD)
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = marker.scale.z = 1.0
    marker.color = ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
    return marker


def _strip(ns, marker_id, xy, rgba, width, kind=Marker.LINE_STRIP) -> Marker:
    marker = _marker(ns, marker_id, kind, rgba)
    marker.points = _points(xy)
    marker.scale.x = width
    return marker


def _closed(polygon: np.ndarray) -> np.ndarray:
    return np.vstack([polygon, polygon[:1]])


def _point(xy) -> Point:
    xy = np.asarray(xy, float).reshape(-1).tolist()
    return Point(x=xy[0], y=xy[1], z=xy[2] if len(xy) > 2 else 0.0)


def _points(xy: np.ndarray) -> list:
    """Return Points for rows of (x, y) or (x, y, z)."""
    xy = np.asarray(xy, float).reshape(-1, np.shape(xy)[-1])
    if xy.shape[1] == 2:
        xy = np.column_stack([xy, np.zeros(len(xy))])
    return [Point(x=x, y=y, z=z) for x, y, z in xy.tolist()]


def _array(markers, frame_id: str, stamp) -> MarkerArray:
    for marker in markers:
        marker.header.frame_id = frame_id
        marker.header.stamp = stamp
    return MarkerArray(markers=markers)
