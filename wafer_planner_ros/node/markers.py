"""
RViz/Foxglove markers of the cell, the roadmap, the latest plan and the arm, as CDR bytes.

Two frames. The cell (enclosure, obstacles, the robot at every station configuration with
its wafer and labels, the wafer trace and robot outlines of a plan) is drawn in
``frame_id``, the cell's plane at z = 0. Joint space (the roadmap's nodes and edges, the
stations' configurations and a plan's joint-space path) is drawn in a cube of its own frame,
``joint_space_frame(frame_id)``: each joint's range is mapped onto one side of the cube
(shoulder -> x, elbow -> y, wrist -> z, in the robot's joint names), whose edges are
labelled with the joint and its range. ``joint_space_offset`` is where that frame sits in
the cell's frame, beside the cell: a static transform (the node publishes it on
``/tf_static`` where ``tf2_msgs`` is installed) lets a viewer show both frames at once.

The markers are built from arrays and encoded straight to bytes (``service.marker_cdr``);
nothing here imports ROS.
"""

from typing import List, Tuple

import numpy as np

from wafer_planner_ros.geometry.kinematics import elbow_words
from wafer_planner_ros.service.marker_cdr import Action, Marker, marker_array, Shape

OUTLINES = 12
"""Robot outlines drawn along a plan."""
PATH_SAMPLES = 400
"""Samples of a plan's curve drawn in joint space and as the wafer trace."""
LABEL_HEIGHT = 0.03
"""m: the height of a text label's letters."""
LABEL_Z = 0.12
"""m: labels float above the robot (the thickest link is 0.12 m across in the default cell)."""
WAFER_THICKNESS = 0.004
"""m: the drawn wafer disc's thickness."""
JOINT_SPACE_SUFFIX = '_joint_space'

COLOURS = {
    'enclosure': (0.75, 0.75, 0.75, 1.0),        # grey
    'obstacles': (0.95, 0.45, 0.10, 1.0),        # orange
    'stations': (0.20, 0.45, 1.00, 0.6),         # blue, see-through: the links overlap
    'station_wafers': (0.55, 0.85, 1.00, 0.45),  # pale blue, see-through
    'station_labels': (1.00, 1.00, 1.00, 1.0),   # white
    'roadmap_nodes': (0.30, 0.85, 0.30, 1.0),    # green
    'roadmap_edges': (0.10, 0.45, 0.10, 0.25),   # dark green, faint
    'joint_space_box': (0.50, 0.50, 0.50, 1.0),  # mid grey
    'joint_space_labels': (0.85, 0.85, 0.85, 1.0),
    'ports': (0.85, 0.05, 0.05, 1.0),             # red: each port's axis, mouth to pick/place
    'path_joint_space': (1.00, 0.85, 0.10, 1.0),  # yellow
    'robot': (0.00, 0.85, 0.85, 0.7),            # cyan: the outlines along a plan
    'arm': (0.10, 0.80, 0.55, 1.0),              # green: the simulated arm (node.sim)
    'arm_wafer': (0.55, 0.85, 1.00, 0.9),        # pale blue: its wafer
}
"""The colour (r, g, b, a) of each namespace."""
WAFER_TRACE_COLOURS = ((1.00, 0.15, 0.60, 1.0), (0.55, 0.15, 1.00, 1.0))
"""The wafer trace's colour at the start (magenta) and the end (violet) of the motion."""


def joint_space_frame(frame_id: str) -> str:
    """Return the frame of the joint-space markers: ``<frame_id>_joint_space``."""
    return frame_id + JOINT_SPACE_SUFFIX


def joint_space_offset(cell) -> np.ndarray:
    """
    Return the joint-space frame's origin in the cell's frame (m), shape (3,).

    The frame is not rotated: the translation is the whole transform. The cube stands
    beside the cell on its +x side, a fifth of its size away, its base on the cell's plane.
    """
    low, high = cell.boundary.min(axis=0), cell.boundary.max(axis=0)
    size = _cube_size(cell)
    return np.array([high[0] + 0.2 * size, low[1], 0.0])


def roadmap_markers(cell, roadmap, frame_id: str, stamp) -> bytes:
    """Return the serialised ``MarkerArray`` of ``roadmap_scene``."""
    return marker_array(roadmap_scene(cell, roadmap, frame_id, stamp))


def path_markers(cell, result, frame_id: str, stamp) -> bytes:
    """Return the serialised ``MarkerArray`` of ``path_scene``."""
    return marker_array(path_scene(cell, result.trajectory, frame_id, stamp))


def arm_markers(cell, q, frame_id: str, stamp) -> bytes:
    """Return the serialised ``MarkerArray`` of ``arm_scene``."""
    return marker_array(arm_scene(cell, q, frame_id, stamp))


def arm_scene(cell, q, frame_id: str, stamp) -> List[Marker]:
    """
    Return the markers of the arm at one configuration ``q`` (rad, (3,)), in ``frame_id``.

    Drawn as a station's robot is (its links as capsules, the wafer disc at the wafer
    centre), opaque, in the namespaces ``arm_wafer``, ``arm`` and ``arm_link_ends`` with
    fixed ids: each publication moves the one arm (``node.sim``).
    """
    joints = cell.robot.arm.joint_points(np.asarray(q, float)[None])
    return _bodies(_factory(frame_id, stamp), cell.robot, joints,
                   ('arm_wafer', 'arm', 'arm_link_ends'))


def roadmap_scene(cell, roadmap, frame_id: str, stamp) -> List[Marker]:
    """
    Return the markers of a roadmap publication, a ``DELETEALL`` first.

    ``DELETEALL`` clears what a previous roadmap drew (a rebuild may have fewer stations or
    obstacles). Then, in ``frame_id``: the enclosure, the obstacles, and at every station
    configuration the wafer (a disc of the wafer's radius), the links (capsules of their
    radii: a cylinder each, spheres at the joints) and a label naming the station and its
    elbow branch, and each port's axis from its mouth (the retracted pose's wafer centre) to
    its pick/place pose; in the joint-space frame: the cube, its axis labels, the roadmap's nodes
    and edges and the stations' configurations. ``stamp``: a ROS time (``sec``,
    ``nanosec``) or a (sec, nanosec) pair.
    """
    cell_marker = _factory(frame_id, stamp)
    joint_marker = _factory(joint_space_frame(frame_id), stamp)
    markers = [cell_marker('', 0, Shape.ARROW, action=Action.DELETEALL, color=(0, 0, 0, 0))]
    markers.append(_line(cell_marker, 'enclosure', 0, _closed(cell.boundary), 0.01))
    markers += [_line(cell_marker, 'obstacles', k, _closed(polygon), 0.01)
                for k, polygon in enumerate(cell.obstacles)]
    names, configs = _station_configs(cell)
    markers += _stations(cell, cell_marker, names, configs)
    axes = [(port.retracted, port.inside_center) for port in cell.port_model.ports]
    if axes:
        markers.append(_line(cell_marker, 'ports', 0, np.array(axes).reshape(-1, 2), 0.01,
                             Shape.LINE_LIST))
    box = _JointBox(cell)
    nodes = box.place(roadmap.nodes)
    markers += box.frame_markers(joint_marker, cell.robot.joint_names)
    markers.append(joint_marker('roadmap_nodes', 0, Shape.POINTS, points=nodes,
                                scale=(0.008, 0.008, 0.0)))
    markers.append(joint_marker('roadmap_edges', 0, Shape.LINE_LIST,
                                points=nodes[np.asarray(roadmap.edges).reshape(-1)],
                                scale=(0.001, 0.0, 0.0)))
    if len(configs):
        markers.append(joint_marker('joint_space_stations', 0, Shape.SPHERE_LIST,
                                    points=box.place(np.array(configs)),
                                    scale=(0.03, 0.03, 0.03), color=COLOURS['stations']))
    return markers


def path_scene(cell, trajectory, frame_id: str, stamp) -> List[Marker]:
    """
    Return the markers of a plan (``trajectory``: a ``Trajectory``).

    In the joint-space frame the path through joint space; in ``frame_id`` the wafer
    centre's trace, coloured from magenta at the start to violet at the end
    (``WAFER_TRACE_COLOURS``), and the robot's outline (its links as lines) at
    ``OUTLINES`` instants.
    """
    cell_marker = _factory(frame_id, stamp)
    joint_marker = _factory(joint_space_frame(frame_id), stamp)
    arm = cell.robot.arm
    q = trajectory.evaluate(np.linspace(0.0, trajectory.duration, PATH_SAMPLES))
    along = np.linspace(0.0, 1.0, len(q))[:, None]
    start, end = (np.array(c) for c in WAFER_TRACE_COLOURS)
    joints = arm.joint_points(trajectory.evaluate(np.linspace(0.0, trajectory.duration,
                                                              OUTLINES)))
    segments = np.stack([joints[:, :-1], joints[:, 1:]], axis=2).reshape(-1, 2)
    return [
        joint_marker('path_joint_space', 0, Shape.LINE_STRIP, points=_JointBox(cell).place(q),
                     scale=(0.006, 0.0, 0.0)),
        cell_marker('wafer_trace', 0, Shape.LINE_STRIP, points=arm.wafer_center(q),
                    scale=(0.006, 0.0, 0.0), color=WAFER_TRACE_COLOURS[0],
                    colors=start + (end - start) * along),
        _line(cell_marker, 'robot', 0, segments, 0.01, Shape.LINE_LIST),
    ]


# ----------------------------------------------------------------- stations


def _station_configs(cell) -> Tuple[List[Tuple[str, int]], List[np.ndarray]]:
    """Return (station name, elbow branch) and q of every station configuration."""
    names, configs = [], []
    for name, station in sorted(cell.stations.items()):
        for config in station.configs:
            names.append((name, config.elbow))
            configs.append(np.asarray(config.q, float))
    return names, configs


def _stations(cell, cell_marker, names, configs) -> List[Marker]:
    if not configs:
        return []
    joints = cell.robot.arm.joint_points(np.array(configs))  # (K, 4, 2)
    markers = _bodies(cell_marker, cell.robot, joints,
                      ('station_wafers', 'stations', 'station_link_ends'))
    offsets = _label_offsets(names, joints[:, 1, 1])
    for k, ((name, elbow), centre) in enumerate(zip(names, joints[:, 3])):
        markers.append(cell_marker(
            'station_labels', k, Shape.TEXT_VIEW_FACING,
            position=(centre[0], centre[1] + offsets[k], LABEL_Z),
            scale=(0.0, 0.0, LABEL_HEIGHT), text=f'{name} ({elbow_words(elbow)})'))
    return markers


def _bodies(cell_marker, robot, joints: np.ndarray, namespaces) -> List[Marker]:
    """
    Return the wafers, links and link ends of the robot at K configurations.

    ``joints``: (K, 4, 2) their ``joint_points``; ``namespaces``: those of the wafers (a
    disc each), the links (a cylinder of its radius each, id 3 k + link) and the link ends
    (a sphere list per link, in the links' colour).
    """
    wafer_ns, link_ns, ends_ns = namespaces
    markers = []
    for k, centre in enumerate(joints[:, 3]):
        markers.append(cell_marker(
            wafer_ns, k, Shape.CYLINDER, position=(*centre, 0.0),
            scale=(2.0 * robot.wafer_radius, 2.0 * robot.wafer_radius, WAFER_THICKNESS)))
    starts, ends = joints[:, :3], joints[:, 1:]
    step = ends - starts
    lengths = np.linalg.norm(step, axis=-1)
    angle = np.arctan2(step[..., 1], step[..., 0])
    half = np.sqrt(0.5)
    for k in range(len(joints)):
        for i, radius in enumerate(robot.link_radii):
            # A cylinder's axis is its z: turn z a quarter turn about the in-plane normal
            # of the link, onto the link.
            markers.append(cell_marker(
                link_ns, 3 * k + i, Shape.CYLINDER,
                position=(*(0.5 * (starts[k, i] + ends[k, i])), 0.0),
                orientation=(-np.sin(angle[k, i]) * half, np.cos(angle[k, i]) * half, 0.0,
                             half),
                scale=(2.0 * radius, 2.0 * radius, lengths[k, i])))
    for i, radius in enumerate(robot.link_radii):
        ends_of_link = np.concatenate([joints[:, i], joints[:, i + 1]])
        markers.append(cell_marker(ends_ns, i, Shape.SPHERE_LIST,
                                   points=ends_of_link, scale=(2.0 * radius,) * 3,
                                   color=COLOURS[link_ns]))
    return markers


def _label_offsets(names, elbow_y: np.ndarray) -> np.ndarray:
    """
    Return each label's offset along y (m) from its wafer centre.

    A station's two branch labels would sit on one point: they are stacked as two lines,
    the branch whose elbow is further along +y on top (ties: the elbow-right branch).
    """
    offsets = np.zeros(len(names))
    by_station = {}
    for k, (name, _) in enumerate(names):
        by_station.setdefault(name, []).append(k)
    for members in by_station.values():
        if len(members) < 2:
            continue
        order = sorted(members, key=lambda k: (-elbow_y[k], -names[k][1]))
        lines = len(order)
        for row, k in enumerate(order):
            offsets[k] = (0.5 * (lines - 1) - row) * 1.5 * LABEL_HEIGHT
    return offsets


# ----------------------------------------------------------------- joint space


def _cube_size(cell) -> float:
    low, high = cell.boundary.min(axis=0), cell.boundary.max(axis=0)
    return float(high[1] - low[1])


class _JointBox:
    """The joint-space cube, in its own frame: corner (0, 0, 0) to (size, size, size)."""

    def __init__(self, cell):
        self.size = _cube_size(cell)
        self.lower, self.upper = cell.robot.limits.position.T

    def place(self, q: np.ndarray) -> np.ndarray:
        """Return joint configurations (..., 3) as points of the cube (m)."""
        return (np.asarray(q, float) - self.lower) / (self.upper - self.lower) * self.size

    def frame_markers(self, joint_marker, joint_names) -> List[Marker]:
        """Return the cube's edges and the label of each axis (joint name and range)."""
        corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
        pairs = [(a, b) for a in range(8) for b in range(a + 1, 8)
                 if np.sum(np.abs(corners[a] - corners[b])) == 1]
        markers = [_line(joint_marker, 'joint_space_box', 0,
                         corners[np.array(pairs).reshape(-1)] * self.size, 0.003,
                         Shape.LINE_LIST)]
        away = 2.0 * LABEL_HEIGHT  # off the edge, outwards
        for axis, name in enumerate(joint_names):
            where = np.full(3, -away)
            where[axis] = 0.5 * self.size  # beside the edge along the axis through 0
            low, high = np.degrees([self.lower[axis], self.upper[axis]])
            markers.append(joint_marker(
                'joint_space_labels', axis, Shape.TEXT_VIEW_FACING, position=where,
                scale=(0.0, 0.0, LABEL_HEIGHT),
                text=f'{"xyz"[axis]}: {name} ({low:.0f} to {high:.0f} deg)'))
        markers.append(joint_marker(
            'joint_space_labels', 3, Shape.TEXT_VIEW_FACING,
            position=(0.5 * self.size, 0.5 * self.size, self.size + 2.0 * LABEL_HEIGHT),
            scale=(0.0, 0.0, 1.5 * LABEL_HEIGHT), text='joint space'))
        return markers


# ----------------------------------------------------------------- building blocks


def _factory(frame_id: str, stamp):
    """Return ``make(ns, id, type, **fields)``: a marker in ``frame_id`` at ``stamp``."""
    stamp = (int(stamp.sec), int(stamp.nanosec)) if hasattr(stamp, 'sec') else \
        (int(stamp[0]), int(stamp[1]))

    def make(ns: str, marker_id: int, kind: Shape, **fields) -> Marker:
        fields.setdefault('color', COLOURS.get(ns, (1.0, 1.0, 1.0, 1.0)))
        if 'points' in fields:
            fields['points'] = _xyz(fields['points'])
        return Marker(frame_id=frame_id, stamp=stamp, ns=ns, id=marker_id, type=kind,
                      **fields)
    return make


def _line(make, ns: str, marker_id: int, points, width: float,
          kind: Shape = Shape.LINE_STRIP) -> Marker:
    return make(ns, marker_id, kind, points=points, scale=(width, 0.0, 0.0))


def _closed(polygon: np.ndarray) -> np.ndarray:
    return np.vstack([polygon, polygon[:1]])


def _xyz(points) -> np.ndarray:
    """Return rows of (x, y) or (x, y, z) as (N, 3), z = 0 where not given."""
    points = np.asarray(points, float)
    points = points.reshape(-1, points.shape[-1])
    if points.shape[1] == 2:
        return np.column_stack([points, np.zeros(len(points))])
    return points
