"""
The RViz/Foxglove markers: their bytes, and what a cell engineer sees in them.

The bytes are read back by rclpy and by rosbags and compared with the message objects
the node used to build; what they show: stations with their wafer and link widths, labels
per elbow branch, joint space in its own frame, a colour per kind of thing.
"""

import dataclasses
import struct

from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point
from node_harness import wait_for
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import get_typestore, Stores
from sensor_msgs.msg import CompressedImage as ImageMsg
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker as MarkerMsg, MarkerArray, MeshFile as MeshFileMsg
from visualization_msgs.msg import UVCoordinate

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.geometry.kinematics import elbow_words
from wafer_planner_ros.node import markers
from wafer_planner_ros.planner import Planner
from wafer_planner_ros.service.marker_cdr import Action, CompressedImage, Marker
from wafer_planner_ros.service.marker_cdr import marker_array, MeshFile, Shape
import yaml

STAMP = (1795333932, 669000000)
TYPE = 'visualization_msgs/msg/MarkerArray'
STORE = get_typestore(Stores.ROS2_JAZZY)
JOINT_SPACE_NAMESPACES = {'roadmap_nodes', 'roadmap_edges', 'joint_space_box',
                          'joint_space_labels', 'joint_space_stations', 'path_joint_space'}


@pytest.fixture(scope='module')
def scenes(cell, roadmap):
    """Return the roadmap and path scenes of each test cell (one station pair planned)."""
    result = Planner(cell, roadmap).plan(*_a_pair(cell))
    return (markers.roadmap_scene(cell, roadmap, 'efem', STAMP),
            markers.path_scene(cell, result.trajectory, 'efem', STAMP))


def _a_pair(cell):
    names = sorted(cell.stations)
    ports = [n for n in names if n.startswith('loadport')]
    locks = [n for n in names if n.startswith('loadlock')]
    return ports[0], locks[-1]


def _decoded(scene) -> list:
    return deserialize_message(marker_array(scene), MarkerArray).markers


# ----------------------------------------------------------------- the bytes


def _object_path(marker: Marker) -> MarkerMsg:
    """Build the message as the node used to: message objects, a Point per point."""
    msg = MarkerMsg(ns=marker.ns, id=marker.id, type=int(marker.type),
                    action=int(marker.action), text=marker.text,
                    frame_locked=marker.frame_locked, texture_resource=marker.texture_resource,
                    mesh_resource=marker.mesh_resource,
                    mesh_use_embedded_materials=marker.mesh_use_embedded_materials)
    msg.header.frame_id = marker.frame_id
    msg.header.stamp = Time(sec=marker.stamp[0], nanosec=marker.stamp[1])
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z = (float(v) for v in marker.position)
    o.x, o.y, o.z, o.w = (float(v) for v in marker.orientation)
    msg.scale.x, msg.scale.y, msg.scale.z = (float(v) for v in marker.scale)
    msg.color = ColorRGBA(**dict(zip('rgba', (float(v) for v in marker.color))))
    msg.lifetime = Duration(sec=marker.lifetime[0], nanosec=marker.lifetime[1])
    msg.points = [Point(x=x, y=y, z=z) for x, y, z in np.asarray(marker.points).tolist()]
    msg.colors = [ColorRGBA(r=r, g=g, b=b, a=a)
                  for r, g, b, a in np.asarray(marker.colors).tolist()]
    msg.texture = ImageMsg(format=marker.texture.format, data=list(marker.texture.data))
    msg.texture.header.frame_id = marker.texture.frame_id
    msg.texture.header.stamp = Time(sec=marker.texture.stamp[0],
                                    nanosec=marker.texture.stamp[1])
    msg.uv_coordinates = [UVCoordinate(u=u, v=v)
                          for u, v in np.asarray(marker.uv_coordinates).tolist()]
    msg.mesh_file = MeshFileMsg(filename=marker.mesh_file.filename,
                                data=list(marker.mesh_file.data))
    return msg


def _summary(m) -> tuple:
    """Return a marker's fields as plain values, from rclpy's message or rosbags'."""
    def array(items, names):  # rclpy and rosbags: lists of structs
        return np.array([[getattr(i, n) for n in names] for i in items], float).reshape(
            -1, len(names)).round(12).tolist()

    pose, texture = m.pose, m.texture
    return (m.header.frame_id, m.header.stamp.sec, m.header.stamp.nanosec, m.ns, m.id,
            m.type, m.action, pose.position.x, pose.position.y, pose.position.z,
            pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w,
            m.scale.x, m.scale.y, m.scale.z, m.color.r, m.color.g, m.color.b, m.color.a,
            m.lifetime.sec, m.lifetime.nanosec, bool(m.frame_locked),
            array(m.points, 'xyz'), array(m.colors, 'rgba'), m.texture_resource,
            texture.header.frame_id, texture.header.stamp.sec, texture.format,
            bytes(bytearray(texture.data)), array(m.uv_coordinates, 'uv'), m.text,
            m.mesh_resource, m.mesh_file.filename, bytes(bytearray(m.mesh_file.data)),
            bool(m.mesh_use_embedded_materials))


@pytest.mark.slow
def test_the_bytes_read_back_as_the_object_path_gives_with_rclpy_and_rosbags(scenes):
    for scene in scenes:
        data = marker_array(scene)
        expected = deserialize_message(
            serialize_message(MarkerArray(markers=[_object_path(m) for m in scene])),
            MarkerArray)
        got = deserialize_message(data, MarkerArray)
        assert got == expected
        independent = STORE.deserialize_cdr(data, TYPE)
        assert [_summary(m) for m in independent.markers] == \
            [_summary(m) for m in expected.markers]
        # rosbags writes the same bytes back (padding zero-filled, as ours).
        assert bytes(STORE.serialize_cdr(independent, TYPE)) == data


def _every_field() -> Marker:
    return Marker(
        frame_id='f', stamp=(-3, 7), ns='ns1', id=-42, type=Shape.TRIANGLE_LIST,
        action=Action.ADD, position=(0.5, -1.25, 2.0), orientation=(0.1, 0.2, 0.3, 0.9),
        scale=(1.5, 2.5, 3.5), color=(0.25, 0.5, 0.75, 1.0), lifetime=(4, 5),
        frame_locked=True, points=np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]),
        colors=np.array([[0.5, 0.25, 0.125, 1.0], [1.0, 0.0, 0.5, 0.25]]),
        texture_resource='embedded://t',
        texture=CompressedImage(stamp=(8, 9), frame_id='cam', format='png', data=b'\x89PNGx'),
        uv_coordinates=np.array([[0.0, 0.5], [1.0, 0.25]]), text='héllo',
        mesh_resource='package://m.dae', mesh_file=MeshFile('m.stl', b'\x01\x02\x03'),
        mesh_use_embedded_materials=True)


def test_every_field_is_where_jazzy_puts_it():
    data = marker_array([_every_field()])
    # (field, its bytes); 'pad' is the alignment of the next field, from the payload start.
    layout = [
        ('encapsulation', b'\x00\x01\x00\x00'), ('markers', struct.pack('<I', 1)),
        ('header.stamp', struct.pack('<iI', -3, 7)), ('header.frame_id', b'\x02\0\0\0f\0'),
        ('pad', b'\0\0'), ('ns', b'\x04\0\0\0ns1\0'),
        ('id, type, action', struct.pack('<iii', -42, 11, 0)),
        ('pose', struct.pack('<7d', 0.5, -1.25, 2.0, 0.1, 0.2, 0.3, 0.9)),
        ('scale', struct.pack('<3d', 1.5, 2.5, 3.5)),
        ('color', struct.pack('<4f', 0.25, 0.5, 0.75, 1.0)),
        ('lifetime', struct.pack('<iI', 4, 5)), ('frame_locked', b'\x01'), ('pad', b'\0\0\0'),
        ('points', struct.pack('<I', 2)),  # at 148: the doubles start at 152, aligned
        ('points[]', struct.pack('<6d', 1, 2, 3, 4, 5, 6)),
        ('colors', struct.pack('<I8f', 2, 0.5, 0.25, 0.125, 1.0, 1.0, 0.0, 0.5, 0.25)),
        ('texture_resource', struct.pack('<I', 13) + b'embedded://t\0'), ('pad', b'\0\0\0'),
        ('texture.header', struct.pack('<iII', 8, 9, 4) + b'cam\0'),
        ('texture.format', struct.pack('<I', 4) + b'png\0'),
        ('texture.data', struct.pack('<I', 5) + b'\x89PNGx'), ('pad', b'\0\0\0'),
        ('uv_coordinates', struct.pack('<I4f', 2, 0.0, 0.5, 1.0, 0.25)),
        ('text', struct.pack('<I', 7) + 'héllo'.encode() + b'\0'), ('pad', b'\0'),
        ('mesh_resource', struct.pack('<I', 16) + b'package://m.dae\0'),
        ('mesh_file.filename', struct.pack('<I', 6) + b'm.stl\0'), ('pad', b'\0\0'),
        ('mesh_file.data', struct.pack('<I', 3) + b'\x01\x02\x03'),
        ('mesh_use_embedded_materials', b'\x01')]
    at = 0
    for name, piece in layout:
        assert data[at:at + len(piece)] == piece, f'{name} at {at}'
        at += len(piece)
    assert len(data) == at
    msg = deserialize_message(data, MarkerArray).markers[0]
    assert (msg.texture.format, bytes(msg.texture.data), msg.text) == ('png', b'\x89PNGx',
                                                                       'héllo')
    assert [(c.u, c.v) for c in msg.uv_coordinates] == [(0.0, 0.5), (1.0, 0.25)]
    assert (msg.mesh_file.filename, bytes(msg.mesh_file.data)) == ('m.stl', b'\x01\x02\x03')
    assert msg.mesh_use_embedded_materials and msg.frame_locked
    assert msg == deserialize_message(serialize_message(_object_path(_every_field())),
                                      MarkerMsg)
    independent = STORE.deserialize_cdr(data, TYPE)
    assert bytes(STORE.serialize_cdr(independent, TYPE)) == data


@pytest.mark.parametrize('frame_id', ['', 'a', 'ab', 'abc', 'abcd', 'efem_joint_space'])
@pytest.mark.parametrize('points', [0, 1])
def test_strings_of_every_length_shift_the_rest_as_rclpy_does(frame_id, points):
    # Each length mod 4 of the strings before the pose and the sequences, empty or not:
    # the bytes are as long as rclpy's and both readers find the fields after them.
    marker = Marker(frame_id=frame_id, ns='n', points=np.ones((points, 3)), text='after',
                    mesh_file=MeshFile('m', b'\x07'))
    data = marker_array([marker, marker])
    reference = serialize_message(MarkerArray(markers=[_object_path(marker)] * 2))
    assert len(data) == len(reference)
    for read in (deserialize_message(data, MarkerArray), STORE.deserialize_cdr(data, TYPE)):
        assert [m.text for m in read.markers] == ['after', 'after']
        assert [bytes(bytearray(m.mesh_file.data)) for m in read.markers] == [b'\x07'] * 2


def test_bad_arrays_are_refused_naming_them():
    with pytest.raises(ValueError, match=r"'edges' 3: points must have shape \(N, 3\), got "
                                         r'\(4, 2\)'):
        marker_array([Marker(ns='edges', id=3, points=np.zeros((4, 2)))])
    with pytest.raises(ValueError, match="'x' 0: color must have 4 values, got 3"):
        marker_array([Marker(ns='x', color=(1.0, 0.0, 0.0))])


# ----------------------------------------------------------------- what they show


def test_a_roadmap_publication_starts_by_deleting_all(scenes):
    roadmap_scene, _ = scenes
    decoded = _decoded(roadmap_scene)
    assert decoded[0].action == MarkerMsg.DELETEALL and decoded[0].ns == ''
    assert all(m.action == MarkerMsg.ADD for m in decoded[1:])


def _viewer(shown: dict, array) -> dict:
    """Apply a MarkerArray as RViz and Foxglove do: in order, by (ns, id)."""
    for m in array:
        if m.action == MarkerMsg.DELETEALL:
            for key in [k for k in shown if not m.ns or k[0] == m.ns]:
                del shown[key]
        elif m.action == MarkerMsg.DELETE:
            shown.pop((m.ns, m.id), None)
        else:
            shown[(m.ns, m.id)] = m
    return shown


def test_a_rebuild_with_fewer_stations_leaves_nothing_stale(default_cell, default_roadmap):
    data = yaml.safe_load(default_cell_path().read_text())
    for name in ('loadport3', 'loadlock2'):
        del data['stations'][name]
    smaller = Cell.from_text(yaml.safe_dump(data), 'smaller.yaml')
    first = _decoded(markers.roadmap_scene(default_cell, default_roadmap, 'efem', STAMP))
    second = _decoded(markers.roadmap_scene(smaller, default_roadmap, 'efem', STAMP))
    shown = _viewer(_viewer({}, first), second)
    assert set(shown) == {(m.ns, m.id) for m in second[1:]}
    labels = {m.text for m in shown.values() if m.ns == 'station_labels'}
    assert labels and not any('loadport3' in t or 'loadlock2' in t for t in labels)
    assert sum(m.ns == 'station_wafers' for m in shown.values()) == 6


def _configs(cell):
    return [(name, c.elbow, c.q) for name, station in sorted(cell.stations.items())
            for c in station.configs]


def _position(m) -> np.ndarray:
    return np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z])


def _points(m) -> np.ndarray:
    return np.array([[p.x, p.y, p.z] for p in m.points]).reshape(-1, 3)


def test_a_wafer_disc_at_every_station_configuration(cell, scenes):
    discs = [m for m in _decoded(scenes[0]) if m.ns == 'station_wafers']
    configs = _configs(cell)
    assert len(discs) == len(configs)
    radius = cell.robot.wafer_radius
    for disc, (_, _, q) in zip(discs, configs):
        assert disc.type == MarkerMsg.CYLINDER
        assert np.allclose(_position(disc)[:2], cell.robot.arm.wafer_center(q), atol=1e-12)
        assert disc.scale.x == disc.scale.y == pytest.approx(2.0 * radius)
        assert 0.0 < disc.scale.z <= 0.01  # a thin disc


def _axis(m) -> np.ndarray:
    """Return where a marker's orientation turns its z axis (a cylinder's axis)."""
    x, y, z, w = (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
                  m.pose.orientation.w)
    return np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])


def test_links_are_capsules_of_their_radii(cell, scenes):
    decoded = _decoded(scenes[0])
    cylinders = [m for m in decoded if m.ns == 'stations']
    ends = {m.id: m for m in decoded if m.ns == 'station_link_ends'}
    configs = _configs(cell)
    radii, lengths = cell.robot.link_radii, cell.robot.link_lengths
    assert len(cylinders) == 3 * len(configs) and sorted(ends) == [0, 1, 2]
    for k, (_, _, q) in enumerate(configs):
        joints = cell.robot.arm.joint_points(q)
        for i in range(3):
            link = cylinders[3 * k + i]
            assert link.type == MarkerMsg.CYLINDER
            assert (link.scale.x, link.scale.y) == pytest.approx((2 * radii[i], 2 * radii[i]))
            assert link.scale.z == pytest.approx(lengths[i])
            middle = 0.5 * (joints[i] + joints[i + 1])
            assert np.allclose(_position(link), [*middle, 0.0], atol=1e-12)
            direction = (joints[i + 1] - joints[i]) / lengths[i]
            assert np.allclose(_axis(link), [*direction, 0.0], atol=1e-12)
            # The rounded ends: a sphere of the link's radius at both of its joints.
            assert ends[i].type == MarkerMsg.SPHERE_LIST
            assert ends[i].scale.x == pytest.approx(2 * radii[i])
            for joint in (joints[i], joints[i + 1]):
                assert np.min(np.linalg.norm(_points(ends[i])[:, :2] - joint, axis=1)) < 1e-12


def test_labels_name_the_branch_in_words_at_distinct_places(cell, scenes):
    labels = [m for m in _decoded(scenes[0]) if m.ns == 'station_labels']
    configs = _configs(cell)
    assert [m.text for m in labels] == [
        f'{name} (elbow {"right" if elbow > 0 else "left"})' for name, elbow, _ in configs]
    assert all(m.type == MarkerMsg.TEXT_VIEW_FACING for m in labels)
    for name in cell.stations:
        places = [_position(m) for m, c in zip(labels, configs) if c[0] == name]
        for a in range(len(places)):
            for b in range(a + 1, len(places)):
                # A line apart at least: the two texts do not overlap.
                assert np.linalg.norm(places[a] - places[b]) >= labels[0].scale.z


def test_branch_words_follow_the_elbow_side():
    # q2 > 0 turns the forearm counter-clockwise: the elbow is on the right of the line
    # from the shoulder to the wrist.
    cell = Cell.from_yaml(default_cell_path())
    for station in cell.stations.values():
        for config in station.configs:
            base, elbow, wrist = cell.robot.arm.joint_points(config.q)[:3]
            line, to_elbow = wrist - base, elbow - base
            side = 'right' if line[0] * to_elbow[1] - line[1] * to_elbow[0] < 0 else 'left'
            assert elbow_words(config.elbow) == f'elbow {side}'


def test_joint_space_is_a_labelled_cube_in_its_own_frame(cell, roadmap, scenes):
    frame = markers.joint_space_frame('efem')
    assert frame == 'efem_joint_space'
    for scene in scenes:
        for m in _decoded(scene):
            assert m.header.frame_id == (frame if m.ns in JOINT_SPACE_NAMESPACES else 'efem'), \
                m.ns
    decoded = {(m.ns, m.id): m for m in _decoded(scenes[0])}
    lower, upper = cell.robot.limits.position.T
    size = float(np.ptp(cell.boundary[:, 1]))
    nodes = _points(decoded['roadmap_nodes', 0])
    assert np.allclose(nodes, (roadmap.nodes - lower) / (upper - lower) * size, atol=1e-12)
    edges = _points(decoded['roadmap_edges', 0])
    assert len(edges) == 2 * roadmap.edge_count
    box = _points(decoded['joint_space_box', 0])
    assert np.allclose(box.min(axis=0), 0.0) and np.allclose(box.max(axis=0), size)
    assert nodes.min() >= 0.0 and nodes.max() <= size
    # Each axis is labelled with the robot's joint name and its range in degrees, beside
    # the cube's edge along that axis.
    for axis, name in enumerate(cell.robot.joint_names):
        label = decoded['joint_space_labels', axis]
        low, high = np.degrees([lower[axis], upper[axis]])
        assert label.text == f'{"xyz"[axis]}: {name} ({low:.0f} to {high:.0f} deg)'
        where = _position(label)
        assert where[axis] == pytest.approx(size / 2)
        assert all(where[other] < 0.0 for other in range(3) if other != axis)
    # Placed by its transform, the cube stands beside the cell, not on it.
    offset = markers.joint_space_offset(cell)
    assert offset[2] == 0.0
    assert (box + offset)[:, 0].min() > cell.boundary[:, 0].max()
    # The stations, in joint space.
    stations = _points(decoded['joint_space_stations', 0])
    assert np.allclose(stations, (np.array([c[2] for c in _configs(cell)]) - lower)
                       / (upper - lower) * size)


def test_the_frame_id_names_both_frames(cell, roadmap):
    decoded = _decoded(markers.roadmap_scene(cell, roadmap, 'cell_a', Time(sec=5, nanosec=6)))
    assert {m.header.frame_id for m in decoded} == {'cell_a', 'cell_a_joint_space'}
    assert {(m.header.stamp.sec, m.header.stamp.nanosec) for m in decoded} == {(5, 6)}


def _colours(decoded) -> dict:
    found = {}
    for m in decoded:
        if m.action != MarkerMsg.ADD or m.type == MarkerMsg.TEXT_VIEW_FACING \
                or m.ns in ('joint_space_box', 'joint_space_stations'):
            continue
        group = 'stations' if m.ns == 'station_link_ends' else m.ns
        colours = [m.color] + list(m.colors)
        found.setdefault(group, set()).update((c.r, c.g, c.b) for c in colours)
    return found


def test_each_kind_of_thing_has_its_own_colour(cell, scenes):
    found = _colours(_decoded(scenes[0]) + _decoded(scenes[1]))
    expected = {'enclosure', 'stations', 'station_wafers', 'roadmap_nodes', 'roadmap_edges',
                'ports', 'path_joint_space', 'wafer_trace', 'robot'} | (
                    {'obstacles'} if len(cell.obstacles) else set())
    assert set(found) == expected
    for a in found:
        for b in found:
            if a < b:
                gap = min(np.linalg.norm(np.subtract(x, y)) for x in found[a] for y in found[b])
                assert gap > 0.25, (a, b, gap)
    # The wafer trace is coloured along time: the start and the end differ.
    trace = next(m for m in _decoded(scenes[1]) if m.ns == 'wafer_trace')
    assert len(trace.colors) == len(trace.points)
    start, end = trace.colors[0], trace.colors[-1]
    assert np.linalg.norm([start.r - end.r, start.g - end.g, start.b - end.b]) > 0.3


def test_each_port_is_drawn_along_its_axis_from_its_mouth_to_its_pick_place_pose(
        cell, scenes):
    ports = next(m for m in _decoded(scenes[0]) if m.ns == 'ports')
    segments = _points(ports)[:, :2].reshape(-1, 2, 2)
    assert len(segments) == len(cell.stations)
    arm = cell.robot.arm
    for station in cell.stations.values():
        inside = station.inside[0]
        retracted = {c.elbow: c.q for c in station.configs}[inside.elbow]
        wanted = np.array([arm.wafer_center(retracted), arm.wafer_center(inside.q)])
        assert np.abs(segments - wanted).max(axis=(1, 2)).min() < 1e-6, station.name
        assert np.linalg.norm(wanted[1] - wanted[0]) == pytest.approx(station.port.depth)


def test_the_path_markers_follow_the_plan(cell, roadmap):
    result = Planner(cell, roadmap).plan(*_a_pair(cell))
    decoded = {m.ns: m for m in deserialize_message(
        markers.path_markers(cell, result, 'efem', STAMP), MarkerArray).markers}
    trace = _points(decoded['wafer_trace'])
    assert np.allclose(trace[0, :2], cell.robot.arm.wafer_center(result.start_q), atol=1e-9)
    assert np.allclose(trace[-1, :2], cell.robot.arm.wafer_center(result.goal_q), atol=1e-9)
    lower, upper = cell.robot.limits.position.T
    size = float(np.ptp(cell.boundary[:, 1]))
    path = _points(decoded['path_joint_space'])
    assert np.allclose(path[[0, -1]], (np.array([result.start_q, result.goal_q]) - lower)
                       / (upper - lower) * size, atol=1e-9)
    outline = _points(decoded['robot'])
    assert len(outline) == 2 * 3 * markers.OUTLINES
    assert np.allclose(outline[0, :2], cell.robot.base)


# ----------------------------------------------------------------- through the node


def test_the_node_latches_them_and_publishes_the_path(harness, default_cell, default_roadmap):
    inbox = harness.subscribe_markers()
    paths = []
    harness.peer.create_subscription(MarkerArray, '/wafer_planner/path_markers',
                                     paths.append, 10)
    wait_for(lambda: inbox, 20)
    got = inbox[0].markers
    stamp = (got[0].header.stamp.sec, got[0].header.stamp.nanosec)
    expected = _decoded(markers.roadmap_scene(default_cell, default_roadmap, 'efem', stamp))
    assert list(got) == expected
    harness.send_stations({'id': 'markers-1', 'from': 'loadport2', 'to': 'loadlock1'})
    harness.result('markers-1')
    wait_for(lambda: paths, 20)
    assert {m.ns for m in paths[-1].markers} == {'path_joint_space', 'wafer_trace', 'robot'}
    try:
        from tf2_msgs.msg import TFMessage  # noqa: F401 - a standard ROS install
    except ImportError:
        # Not on this machine: no static transform, and nothing else changes.
        assert harness.peer.count_publishers('/tf_static') == 0
        return
    transforms = []
    harness.peer.create_subscription(TFMessage, '/tf_static', transforms.append,
                                     harness.node._roadmap_pub.qos_profile)
    wait_for(lambda: transforms, 20)
    (transform,) = transforms[0].transforms
    assert (transform.header.frame_id, transform.child_frame_id) == ('efem',
                                                                     'efem_joint_space')
    t = transform.transform.translation
    assert np.allclose([t.x, t.y, t.z], markers.joint_space_offset(default_cell))


def test_markers_dataclass_defaults_are_the_messages():
    assert _summary(deserialize_message(marker_array([Marker()]), MarkerArray).markers[0]) \
        == _summary(deserialize_message(serialize_message(MarkerArray(markers=[MarkerMsg()])),
                                        MarkerArray).markers[0])
    assert {f.name for f in dataclasses.fields(Marker)} >= {
        'texture', 'uv_coordinates', 'mesh_file', 'mesh_use_embedded_materials'}
