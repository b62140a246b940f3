"""Ports: read from the cell file, their channels checked, their margins (``geometry.ports``)."""

import copy

import numpy as np
import pytest
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.errors import CellError
from wafer_planner_ros.geometry.ports import describe_deviation
import yaml


@pytest.fixture()
def document():
    """Return the default cell as a fresh, mutable dict."""
    return yaml.safe_load(default_cell_path().read_text())


def test_every_station_of_every_test_cell_has_a_port_it_can_enter(cell):
    arm = cell.robot.arm
    for name, station in cell.stations.items():
        port = station.port
        assert port is not None and port.station == name
        assert station.inside, name
        for inside in station.inside:
            assert inside.elbow in [c.elbow for c in station.configs]
            np.testing.assert_allclose(arm.wafer_center(inside.q), port.inside_center,
                                       atol=1e-9)
            assert np.cos(arm.heading(inside.q) - port.heading) == pytest.approx(1.0)
            assert cell.clearance_model.clearance(inside.q)[0] > 0.0
        # The retracted pose is where the port's axis starts.
        np.testing.assert_allclose(port.retracted, arm.wafer_center(station.configs[0].q))


def test_the_channel_runs_straight_along_the_axis_on_the_same_branch(default_cell):
    arm = default_cell.robot.arm
    station = default_cell.stations['loadport1']
    port, config = station.port, station.configs[0]
    s = np.linspace(0.0, port.depth, 50)
    q = port.channel(arm, config.q, s)
    assert np.array_equal(q[0], config.q)
    along, across = port.offsets(arm.wafer_center(q))
    np.testing.assert_allclose(along, s, atol=1e-12)
    np.testing.assert_allclose(across, 0.0, atol=1e-12)
    np.testing.assert_allclose(arm.heading(q), port.heading, atol=1e-12)
    assert np.all(np.sign(q[:, 1]) == config.elbow)
    assert np.abs(np.diff(q, axis=0)).max() < 0.1  # continuous: no jump by 2 pi


def test_only_the_branches_that_reach_straight_in_are_offered(default_cell):
    # loadport1: the elbow-left branch would pass its shoulder's limit of pi on the way in.
    assert [c.elbow for c in default_cell.stations['loadport1'].configs] == [1, -1]
    assert [c.elbow for c in default_cell.stations['loadport1'].inside] == [1]
    assert [c.elbow for c in default_cell.stations['loadport2'].inside] == [1, -1]


def test_port_tolerances_have_defaults_and_are_part_of_the_cell(document):
    a = Cell.from_dict(copy.deepcopy(document))
    assert a.stations['loadlock1'].spec['port'] == {
        'depth': 0.35, 'lateral_tolerance': 0.001, 'heading_tolerance': 0.0087}
    document['stations']['loadlock1']['port']['lateral_tolerance'] = 0.002
    b = Cell.from_dict(document)
    assert b.stations['loadlock1'].port.lateral_tolerance == 0.002
    assert a.digest != b.digest
    del document['stations']['loadlock1']['port']
    c = Cell.from_dict(document)
    assert c.stations['loadlock1'].port is None and c.stations['loadlock1'].inside == ()
    assert 'port' not in c.stations['loadlock1'].spec
    assert len(c.port_model) == 16  # four margins of each of the four ports left


@pytest.mark.parametrize('port, path, reason', [
    ({'depth': -0.1}, 'stations.loadport2.port.depth', 'must be > 0'),
    ({}, 'stations.loadport2.port.depth', 'missing'),
    ({'depth': 0.3, 'width': 1}, 'stations.loadport2.port.width', 'unknown key'),
    ({'depth': 0.3, 'lateral_tolerance': 0.2}, 'stations.loadport2.port.lateral_tolerance',
     'must be below the wafer radius'),
    ({'depth': 0.3, 'heading_tolerance': 2.0}, 'stations.loadport2.port.heading_tolerance',
     'must be below pi / 2'),
    ({'depth': 0.9}, 'stations.loadport2.port', 'out of reach 0.'),
    ({'depth': 0.45}, 'stations.loadport2.port', 'wafer vs boundary'),
])
def test_a_bad_port_is_refused_naming_its_key_and_why(document, port, path, reason):
    document['stations']['loadport2']['port'] = port
    with pytest.raises(CellError) as info:
        Cell.from_dict(document)
    assert info.value.path == path
    assert reason in info.value.reason


def test_a_port_without_its_pocket_is_refused_with_where_it_collides(document):
    document['cell']['boundary'] = [[-0.85, -0.45], [0.85, -0.45], [0.85, 0.45], [-0.85, 0.45]]
    with pytest.raises(CellError) as info:
        Cell.from_dict(document)
    assert info.value.path == 'stations.loadport1.port'
    assert 'the straight channel from the retracted pose to 0.35 m inside is not free' in \
        info.value.reason
    assert 'elbow right: in collision 0.0' in info.value.reason   # a few cm in: the wall
    assert 'wafer vs boundary' in info.value.reason


def _at(cell, station, s, offset=0.0, turn=0.0, elbow=1):
    """Return the configuration with the wafer ``s`` m into a port, off its axis and turned."""
    port = cell.stations[station].port
    centre = port.retracted + s * port.axis + offset * port.normal
    return [c for c in cell.robot.arm.inverse(centre, port.heading + turn,
                                              cell.robot.limits.position)
            if c.elbow == elbow][0].q


def test_the_margins_are_positive_exactly_where_the_rule_holds(default_cell):
    model = default_cell.port_model
    k = [p.station for p in model.ports].index('loadport2')
    out = 2 ** -0.5
    cases = [  # (s, offset, turn, margins: left, right, turned left, turned right) by hand
        (0.35, 0.0, 0.0, (0.001, 0.001, 0.001, 0.001)),     # the inside pose: full tolerance
        (0.2, 0.0005, 0.0, (0.0005, 0.0015, 0.001, 0.001)),
        (0.2, -0.002, 0.0, (0.003, -0.001, 0.001, 0.001)),  # 2 mm off the axis: broken
        (0.2, 0.0, 0.0174, (0.001, 0.001, -0.001, 0.003)),  # turned 1 deg: broken
        (-0.03, 0.01, 0.1, (0.04 * out,) * 4),               # in front of the port
        (0.005, 0.16, 0.3, (0.155 * out, 0.161, 0.155 * out, 0.155 * out)),  # sweeping past
        (0.005, 0.003, 0.0, (-0.002 * out, 0.004, 0.001, 0.001)),  # entering 3 mm off
    ]
    for s, offset, turn, expected in cases:
        q = _at(default_cell, 'loadport2', s, offset, turn)
        margins = model.margins(q[None])[0, 4 * k:4 * k + 4]
        np.testing.assert_allclose(margins, expected, atol=1e-9, err_msg=str((s, offset, turn)))
        broken = describe_deviation(model, q)
        assert (broken is not None) == (min(expected) < 0.0)
    assert 'inside the port of loadport2 2.00 mm off its axis (tolerance 1.00 mm)' in \
        describe_deviation(model, _at(default_cell, 'loadport2', 0.2, -0.002))


def test_the_margin_gradient_is_the_derivative_and_the_lipschitz_bound_holds(default_cell):
    model = default_cell.port_model
    rng = np.random.default_rng(3)
    q = np.array([_at(default_cell, 'loadport2', s, y, h) for s, y, h in zip(
        rng.uniform(-0.05, 0.35, 40), rng.uniform(-0.003, 0.003, 40),
        rng.uniform(-0.02, 0.02, 40))])
    values = _assert_the_gradient_is_the_derivative(model, q)
    other = q + rng.uniform(-0.05, 0.05, q.shape)
    change = np.abs(model.margins(other) - values)
    assert np.all(change <= np.abs(other - q) @ model.lipschitz.T + 1e-12)


def test_a_keep_out_round_another_ports_mouth_only_lowers_its_margins(default_cell):
    """
    The optimiser's disc round a mouth: smooth in front of it, never above the rule.

    A port a curve starts or ends at (its mouth is where the curve begins) gets no disc;
    every other port's margins are the rule's, or lower where the wafer is turned within
    the disc's radius of its mouth, so a curve that keeps them keeps the rule.
    """
    model = default_cell.port_model
    names = [p.station for p in model.ports]
    k, own = names.index('loadport2'), names.index('loadport1')
    starting = _at(default_cell, 'loadport1', 0.0)
    kept = model.keeping_out(0.02, starting[None])
    assert kept.keep_out[own] == 0.0 and kept.keep_out[k] == 0.02
    rng = np.random.default_rng(5)
    q = np.array([_at(default_cell, 'loadport2', s, y, h) for s, y, h in zip(
        rng.uniform(-0.04, 0.04, 60), rng.uniform(-0.04, 0.04, 60),
        rng.uniform(-1.0, 1.0, 60))])
    rule, lowered = model.margins(q), kept.margins(q)
    assert np.all(lowered <= rule)
    np.testing.assert_array_equal(lowered[:, 4 * own:4 * own + 4], rule[:, 4 * own:4 * own + 4])
    # Turned 0.3 rad, 1 cm in front of the tip on the axis (its "turned left" margin): the
    # rule's 7.1 mm, the disc's 10 mm short of its radius.
    front = _at(default_cell, 'loadport2', -0.01, 0.0, 0.3)[None]
    turned = 4 * k + 2
    np.testing.assert_allclose(model.margins(front)[0, turned], 0.01 * 2 ** -0.5, atol=1e-9)
    np.testing.assert_allclose(kept.margins(front)[0, turned], -0.01, atol=1e-9)
    _assert_the_gradient_is_the_derivative(kept, q)
    # A path that passes 6 mm in front of the mouth turned breaks the keep-out; one that
    # passes there aligned with the port does not, nor one 3 cm away turned.
    assert kept.breaks_keep_out(np.stack([
        starting, _at(default_cell, 'loadport2', -0.006, 0.0, 0.3)]))
    assert not kept.breaks_keep_out(np.stack([
        starting, _at(default_cell, 'loadport2', -0.006, 0.0, 0.0)]))
    assert not kept.breaks_keep_out(np.stack([
        starting, _at(default_cell, 'loadport2', -0.03, 0.0, 0.3)]))
    # No disc at all (radius 0): the rows' model is the proof's itself.
    motion = default_cell.motion_model
    assert motion.keeping_out(0.0, starting[None]) is motion
    assert motion.keeping_out(0.02, starting[None]) is not motion
    with pytest.raises(ValueError, match='one radius >= 0 per port'):
        type(model)(model.arm, model.ports, [-0.01] * len(model.ports))


def _assert_the_gradient_is_the_derivative(model, q) -> np.ndarray:
    """Check ``margins_gradient`` against forward differences; return the margins."""
    values, gradient = model.margins_gradient(q)
    step = 1e-7
    for i in range(3):
        moved = q.copy()
        moved[:, i] += step
        numeric = (model.margins(moved) - values) / step
        np.testing.assert_allclose(gradient[:, :, i], numeric, atol=1e-5)
    return values
