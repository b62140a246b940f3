"""The cell model: the default cell's values and every validation error a user can make."""

import copy
import warnings

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.errors import CellError
from wafer_planner_ros.geometry.planar import cross2
import yaml


@pytest.fixture()
def document():
    """Return the default cell as a fresh, mutable dict."""
    return yaml.safe_load(default_cell_path().read_text())


def test_default_cell_has_the_spec_values(default_cell):
    cell = default_cell
    assert cell.name == 'efem-3lp-2ll'
    # The enclosure with a pocket for each port: 0.32 m wide, 0.16 m beyond the inside pose.
    assert cell.boundary.tolist() == [
        [-0.85, -0.45], [-0.66, -0.45], [-0.66, -0.77], [-0.34, -0.77], [-0.34, -0.45],
        [0.34, -0.45], [0.34, -0.77], [0.66, -0.77], [0.66, -0.45], [0.85, -0.45],
        [0.85, 0.45], [0.665, 0.45], [0.665, 0.77], [0.345, 0.77], [0.345, 0.45],
        [0.16, 0.45], [0.16, 0.77], [-0.16, 0.77], [-0.16, 0.45], [-0.345, 0.45],
        [-0.345, 0.77], [-0.665, 0.77], [-0.665, 0.45], [-0.85, 0.45]]
    assert cell.obstacles == ()
    r = cell.robot
    assert r.base.tolist() == [0.0, 0.0]
    assert r.joint_names == ('shoulder', 'elbow', 'wrist')
    assert r.link_lengths.tolist() == [0.36, 0.36, 0.22]
    assert r.link_radii.tolist() == [0.06, 0.05, 0.035]
    assert r.wafer_radius == 0.15
    assert r.limits.position.tolist() == [[-3.14159, 3.14159]] * 3
    assert r.limits.velocity.tolist() == [4.2, 8.4, 6.3]
    assert r.limits.acceleration.tolist() == [8.4, 16.8, 12.6]
    assert r.limits.jerk.tolist() == [84.0, 168.0, 126.0]  # 10 x acceleration
    assert r.wafer_limit.xy.tolist() == [0.981, 0.981]
    assert r.wafer_limit.norm is None
    # Empty: the loaded joint limits (none raised in the file), no wafer limit.
    empty = r.limit_sets['empty']
    assert empty.wafer is None and empty.joints.velocity is r.limits.velocity
    assert sorted(cell.stations) == ['loadlock1', 'loadlock2', 'loadport1', 'loadport2',
                                     'loadport3']
    for station in cell.stations.values():
        port = station.port
        assert (port.depth, port.lateral_tolerance, port.heading_tolerance) == \
            (0.35, 0.001, 0.0087)
        np.testing.assert_allclose(port.inside_center, np.array(station.spec['wafer_center'])
                                   + 0.35 * np.array([0.0, np.sign(station.spec['heading'])]),
                                   atol=1e-5)


def test_default_stations_reachable_on_both_branches_at_their_poses(default_cell):
    arm = default_cell.robot.arm
    for station in default_cell.stations.values():
        assert sorted(c.elbow for c in station.configs) == [-1, 1]
        for config in station.configs:
            assert np.sign(config.q[1]) == config.elbow
            assert np.allclose(arm.wafer_center(config.q), station.spec['wafer_center'])
            assert np.isclose(np.cos(arm.heading(config.q) - station.spec['heading']), 1.0)
            assert default_cell.clearance_model.clearance(config.q)[0] > 0


def test_test_cells_cover_obstacles_and_irregular_boundaries(cell):
    start, middle, end = cell.boundary, np.roll(cell.boundary, -1, 0), np.roll(
        cell.boundary, -2, 0)
    reflex = bool(np.any(cross2(middle - start, end - middle) < 0))
    single = [len(c.configs) for c in cell.stations.values()].count(1)  # elbow / joints
    # Each cell is there for what it covers; a cell not listed here fails.
    covers = {
        'efem-3lp-2ll': (0, True, False, 0),  # the paper's, with port pockets, base at 0
        'efem-pillar': (2, True, False, 2),   # obstacles, single-branch stations
        'efem-notched': (0, True, True, 0),    # a reflex corner, the base off the origin
    }
    assert cell.name in covers
    assert (len(cell.obstacles), reflex, bool(np.any(cell.robot.base != 0.0)), single) == \
        covers[cell.name]


def test_station_roles_follow_names(default_cell):
    roles = {name: s.role for name, s in default_cell.stations.items()}
    assert roles['loadport2'] == 'loadport' and roles['loadlock1'] == 'loadlock'


def _set(doc, path, value):
    keys = path.split('.')
    node = doc
    for key in keys[:-1]:
        node = node[key]
    if value is _DELETE:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value


_DELETE = object()

BAD_VALUES = [
    # (key path to change, new value, expected path in message, expected reason)
    ('cell.boundary', [[-0.85, -0.45], [0.85, 0.45], [0.85, -0.45], [-0.85, 0.45]],
     'cell.boundary', 'self-intersecting: edges 0 and 2 cross at (0.000, 0.000)'),
    ('cell.obstacles', [[[-0.8, 0.3], [-0.7, 0.3], [-0.7, 0.4], [-0.75, 0.3], [-0.8, 0.4]]],
     'cell.obstacles[0]', 'self-intersecting: edges 0 and 2 meet at (-0.750, 0.300)'),
    ('cell.boundary', [[0, 0], [1, 0]], 'cell.boundary', 'at least 3'),
    ('cell.boundary', [[0, 0], [1, 0], [2, 0]], 'cell.boundary', 'zero area'),
    ('cell.boundary', [[0, 0], [1, 0], [1, 'x']], 'cell.boundary[2][1]', 'must be a number'),
    ('cell.obstacles', [[[2, 2], [3, 2], [3, 3]]], 'cell.obstacles[0]', 'outside'),
    ('robot.link_radii', [0.06, 0.0, 0.035], 'robot.link_radii[1]', 'must be > 0'),
    ('robot.link_lengths', [-0.36, 0.36, 0.22], 'robot.link_lengths[0]', 'must be > 0'),
    ('robot.link_lengths', [0.36, 0.36], 'robot.link_lengths', 'list of 3'),
    ('robot.wafer_radius', 0, 'robot.wafer_radius', 'must be > 0'),
    ('robot.wafer_radius', float('nan'), 'robot.wafer_radius', 'finite'),
    ('robot.base', [2.0, 0.0], 'robot.base', 'not inside'),
    ('robot.joint_names', ['a', 'a', 'b'], 'robot.joint_names', 'unique'),
    ('robot.joint_limits.velocity', [4.2, 8.4, 0.0], 'robot.joint_limits.velocity[2]',
     'must be > 0'),
    ('robot.joint_limits.acceleration', [8.4, 'fast', 12.6],
     'robot.joint_limits.acceleration[1]', 'must be a number'),
    ('robot.joint_limits.position', [[1.0, -1.0], [-3, 3], [-3, 3]],
     'robot.joint_limits.position[0]', 'must be below'),
    ('robot.joint_limits.jerk', [1.0, -1.0, 1.0], 'robot.joint_limits.jerk[1]', 'must be > 0'),
    ('robot.wafer_acceleration_limit', [0.981, -1], 'robot.wafer_acceleration_limit[1]',
     'must be > 0'),
    ('robot.wafer_acceleration_norm_limit', 0.0, 'robot.wafer_acceleration_norm_limit',
     'must be > 0'),
    ('stations.loadport2', {'wafer_center': [1.2, 0.0], 'heading': 0.0}, 'stations.loadport2',
     'unreachable'),
    ('stations.loadport2', {'wafer_center': [0.25, 0.35], 'heading': 1.5708},
     'stations.loadport2', 'in collision (wafer vs boundary, overlap 50.0 mm)'),
    ('stations.loadlock1', {'joints': [-1.5708, 0.0, 0.0]}, 'stations.loadlock1',
     'in collision (elbow link vs boundary)'),
    ('stations.loadlock1', {'joints': [0.0, 4.0, 0.0]}, 'stations.loadlock1.joints[1]',
     'outside the joint limits'),
    ('stations.loadport1.elbow', 2, 'stations.loadport1.elbow', 'must be 1 or -1'),
    ('stations.loadport1.height', 0.3, 'stations.loadport1.height', 'unknown key'),
    ('robot.colour', 'blue', 'robot.colour', 'unknown key'),
    ('extra', 1, 'extra', 'unknown key'),
    ('robot.wafer_radius', _DELETE, 'robot.wafer_radius', 'missing'),
    ('stations', {}, 'stations', 'non-empty'),
    # Limits that make no physical sense: refused at load, not planned into a traceback.
    ('robot.joint_limits.acceleration', [1e-300, 16.8, 12.6],
     'robot.joint_limits.acceleration[0]', 'too small'),
    ('robot.joint_limits.velocity', [4.2, 5e-324, 6.3], 'robot.joint_limits.velocity[1]',
     'too small'),
    ('robot.joint_limits.jerk', [84.0, 168.0, 1e-9], 'robot.joint_limits.jerk[2]',
     'too small'),
    ('robot.wafer_acceleration_limit', [0.981, 1e-12], 'robot.wafer_acceleration_limit[1]',
     'too small'),
    ('robot.wafer_acceleration_norm_limit', 1e-300, 'robot.wafer_acceleration_norm_limit',
     'too small'),
    ('robot.empty_joint_limits', {'velocity': [8.4, 16.8, 1e-300]},
     'robot.empty_joint_limits.velocity[2]', 'too small'),
    ('robot.empty_joint_limits', {'velocity': [8.4, -1.0, 12.6]},
     'robot.empty_joint_limits.velocity[1]', 'must be > 0'),
    ('robot.empty_joint_limits', {'position': [[-3, 3]] * 3},
     'robot.empty_joint_limits.position', 'unknown key'),
    ('robot.empty_joint_limits', [8.4, 16.8, 12.6], 'robot.empty_joint_limits',
     'must be a mapping'),
    ('robot.joint_limits.position', [[-1e300, 3], [-3, 3], [-3, 3]],
     'robot.joint_limits.position[0][0]', 'not a plausible joint limit'),
    ('cell.boundary', [[-0.85, -0.45], [1e308, -0.45], [0.85, 0.45], [-0.85, 0.45]],
     'cell.boundary[1][0]', 'farther out'),
    ('robot.base', [0.0, -1e300], 'robot.base[1]', 'farther out'),
    ('robot.link_lengths', [0.36, 1e300, 0.22], 'robot.link_lengths[1]', 'longer than 1000 m'),
    ('robot.wafer_radius', 1e300, 'robot.wafer_radius', 'larger than 1000 m'),
    ('stations.loadport1', {'wafer_center': [1e300, 0.0], 'heading': 0.0},
     'stations.loadport1.wafer_center[0]', 'farther out'),
    ('stations.loadport1', {'wafer_center': [0.0, 0.26], 'heading': 1e300},
     'stations.loadport1.heading', 'not a plausible heading'),
    ('robot.clearance_margin', -0.001, 'robot.clearance_margin', 'must be >= 0'),
    ('robot.clearance_margin', 0.05, 'stations.loadport1.port',
     'within the clearance margin of 50.0 mm'),
]


@pytest.mark.parametrize('key, value, path, reason', BAD_VALUES,
                         ids=[f'{b[0]}-{b[3]}' for b in BAD_VALUES])
def test_every_validation_error_names_the_key_path_and_reason(document, key, value, path,
                                                              reason):
    doc = copy.deepcopy(document)
    _set(doc, key, value)
    with pytest.raises(CellError) as info:
        Cell.from_dict(doc)
    assert info.value.path == path
    assert reason in info.value.reason
    assert str(info.value).startswith(f'{path}: ')


def test_station_branch_in_collision_is_dropped_unless_demanded(document):
    # An obstacle on the elbow of loadport1's elbow-down branch (elbow near (-0.27, -0.24)).
    doc = copy.deepcopy(document)
    doc['cell']['obstacles'] = [[[-0.30, -0.27], [-0.24, -0.27], [-0.24, -0.21],
                                 [-0.30, -0.21]]]
    _without_ports(doc)  # the obstacle also blocks loadlock1's one channel
    cell = Cell.from_dict(copy.deepcopy(doc))
    assert [c.elbow for c in cell.stations['loadport1'].configs] == [1]
    doc['stations']['loadport1']['elbow'] = -1
    with pytest.raises(CellError) as info:
        Cell.from_dict(doc)
    assert info.value.path == 'stations.loadport1'
    assert 'in collision' in info.value.reason and 'cell.obstacles[0]' in info.value.reason


def test_unreadable_and_malformed_files(tmp_path):
    with pytest.raises(CellError, match='cannot read'):
        Cell.from_yaml(tmp_path / 'missing.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('cell: [unclosed\n')
    with pytest.raises(CellError, match='not valid YAML'):
        Cell.from_yaml(bad)
    bad.write_text('- just\n- a list\n')
    with pytest.raises(CellError, match='must be a mapping'):
        Cell.from_yaml(bad)


def test_digest_ignores_layout_but_not_values(document, tmp_path):
    a = Cell.from_dict(copy.deepcopy(document))
    reordered = {'stations': document['stations'], 'robot': document['robot'],
                 'cell': document['cell']}
    path = tmp_path / 'cell.yaml'
    path.write_text('# a comment\n' + yaml.safe_dump(reordered, default_flow_style=True))
    assert Cell.from_yaml(path).digest == a.digest
    changed = copy.deepcopy(document)
    changed['robot']['joint_limits']['velocity'][0] = 4.0
    assert Cell.from_dict(changed).digest != a.digest


def test_a_limit_just_inside_an_hour_of_motion_is_accepted(document):
    doc = copy.deepcopy(document)
    # 2 sqrt(1.88 m / a) = 3,000 s: slow, but a real (if odd) cell.
    doc['robot']['wafer_acceleration_limit'] = [8.4e-7, 8.4e-7]
    assert Cell.from_dict(doc).robot.wafer_limit.xy[0] == 8.4e-7


def test_the_clearance_margin_is_kept_by_every_collision_test(document, default_cell):
    doc = copy.deepcopy(document)
    doc['robot']['clearance_margin'] = 0.005
    cell = Cell.from_dict(doc)
    rng = np.random.default_rng(5)
    q = rng.uniform(-np.pi, np.pi, (20000, 3))
    # The fast model: every clearance 5 mm less than without the margin.
    plain = default_cell.clearance_model.body_clearance(q)
    assert np.allclose(cell.clearance_model.body_clearance(q), plain - 0.005, rtol=0,
                       atol=1e-12)
    # The fcl reference agrees: in collision exactly where the plain distance is <= 5 mm
    # (away from the edge of the band, where rounding decides).
    distance = plain.min(axis=1)
    clear_cut = np.abs(distance - 0.005) > 1e-6
    found = cell.fcl_model().in_collision_many(q[clear_cut])
    assert np.array_equal(found, distance[clear_cut] <= 0.005)
    assert found.any() and not found.all()
    assert 0.005 > distance[clear_cut][~found].min() - 0.005 > 0


def test_no_margin_leaves_the_cell_digest_as_it_was(document, default_cell):
    doc = copy.deepcopy(document)
    doc['robot']['clearance_margin'] = 0.0
    assert Cell.from_dict(doc).digest == default_cell.digest
    doc['robot']['clearance_margin'] = 0.001
    assert Cell.from_dict(doc).digest != default_cell.digest


def test_valid_enclosures_the_old_check_refused_are_accepted(document):
    doc = copy.deepcopy(document)
    # An alcove in the loadlock wall (two collinear wall edges that do not touch), written
    # closed and with a vertex twice in a row.
    alcove = [[-0.85, -0.45], [-0.1, -0.45], [-0.1, -0.5], [0.1, -0.5], [0.1, -0.45],
              [0.85, -0.45], [0.85, -0.45], [0.85, 0.45], [-0.85, 0.45], [-0.85, -0.45]]
    doc['cell']['boundary'] = alcove
    _without_ports(doc)  # the pockets are gone
    doc['cell']['obstacles'] = [[[0.7, 0.0], [0.8, 0.0], [0.8, 0.1], [0.7, 0.1]][::-1]]
    cell = Cell.from_dict(doc)
    assert cell.boundary.tolist() == alcove[:6] + alcove[7:9]
    assert cell.notes == (
        'cell.boundary: the last point repeats the first (a closed ring) and was dropped',
        'cell.boundary: vertex 6 repeats vertex 5 and was dropped')
    assert cross2(cell.obstacles[0][1] - cell.obstacles[0][0],
                  cell.obstacles[0][2] - cell.obstacles[0][1]) > 0  # made counter-clockwise


def _without_ports(doc) -> None:
    """Take every station's port out of a cell document."""
    for station in doc['stations'].values():
        station.pop('port', None)


def _key_paths(node, prefix=()):
    """Yield the key path of every value in a parsed cell document."""
    if prefix:
        yield prefix
    items = node.items() if isinstance(node, dict) else \
        enumerate(node) if isinstance(node, list) else ()
    for key, value in items:
        yield from _key_paths(value, prefix + (key,))


_DOCUMENT = yaml.safe_load(default_cell_path().read_text())
_HOSTILE = st.one_of(
    st.sampled_from([0, -1, 1e-300, 5e-324, 1e308, -1e308, 10 ** 400, -10 ** 400, True, None,
                     '', 'x' * 10000, [], {}, [[0, 0], [1, 0], [1, 1]], [1e308] * 3,
                     [[-1e300, 0], [1e300, 0], [0, 1e300]]]),
    st.floats(allow_nan=True, allow_infinity=True), st.integers(),
    st.lists(st.floats(), max_size=4), st.text(max_size=20))


@settings(max_examples=600, deadline=None, derandomize=True, database=None)
@given(st.lists(st.tuples(st.sampled_from(list(_key_paths(_DOCUMENT))), _HOSTILE),
                min_size=1, max_size=3))
def test_any_value_anywhere_gives_a_cell_or_a_short_cell_error(changes):
    doc = copy.deepcopy(_DOCUMENT)
    for path, value in changes:
        node = doc
        try:
            for key in path[:-1]:
                node = node[key]
            node[path[-1]] = value
        except (KeyError, IndexError, TypeError):
            continue  # an earlier change replaced a mapping or list on this path
    with warnings.catch_warnings():
        warnings.simplefilter('error')  # no overflow on the way to the answer either
        try:
            Cell.from_dict(doc)
        except CellError as exc:
            assert len(str(exc)) < 4096


def _fastest_by_lp(distance, v, a, j, duration, steps=400) -> bool:
    """
    Return whether a rest-to-rest motion over ``distance`` fits in ``duration``.

    An independent answer: piecewise-constant jerk on a uniform grid, the limits at the
    grid points, feasibility by linear programming.
    """
    from scipy.optimize import linprog
    dt = duration / steps
    # State after k steps as linear functions of the jerks u_0..u_{k-1}.
    acc, vel, pos = np.zeros(steps), np.zeros(steps), np.zeros(steps)
    rows_a, rows_v = [], []
    for k in range(steps):
        pos = pos + vel * dt + acc * dt ** 2 / 2
        vel = vel + acc * dt
        pos[k] += dt ** 3 / 6
        vel[k] += dt ** 2 / 2
        acc = acc.copy()
        acc[k] += dt
        rows_a.append(acc.copy())
        rows_v.append(vel.copy())
    upper = np.vstack(rows_a + rows_v + [-r for r in rows_a] + [-r for r in rows_v])
    bound = np.concatenate([np.full(steps, a), np.full(steps, v)] * 2)
    result = linprog(np.zeros(steps), A_ub=upper, b_ub=bound,
                     A_eq=np.vstack([pos, vel, acc]), b_eq=[distance, 0.0, 0.0],
                     bounds=[(-j, j)] * steps, method='highs')
    return result.status == 0


@pytest.mark.parametrize('distance, v, a, j', [
    (0.002, 4.2, 8.4, 84.0),     # jerk alone: the acceleration limit is never reached
    (0.4, 4.2, 8.4, 84.0),       # acceleration ramps, no cruise
    (3.0, 4.2, 8.4, 84.0),       # ramps and a cruise at the velocity limit
    (0.1, 1.0, 100.0, 100.0),    # the velocity limit comes before the acceleration limit
    (1.0, 1.0, 100.0, 100.0),
])
def test_the_shortest_motion_is_what_an_independent_optimum_reaches(distance, v, a, j):
    from wafer_planner_ros.cell.limits import JointLimits
    limits = JointLimits(np.zeros((1, 2)), np.array([v]), np.array([a]), np.array([j]))
    shortest = float(limits.shortest_motion([distance])[0])
    assert _fastest_by_lp(distance, v, a, j, 1.01 * shortest)
    assert not _fastest_by_lp(distance, v, a, j, 0.99 * shortest)
    # Without a jerk limit: the same as a very large one.
    free = JointLimits(np.zeros((1, 2)), np.array([v]), np.array([a]))
    stiff = JointLimits(np.zeros((1, 2)), np.array([v]), np.array([a]), np.array([1e12]))
    assert free.shortest_motion([distance])[0] == pytest.approx(
        stiff.shortest_motion([distance])[0], rel=1e-5)
