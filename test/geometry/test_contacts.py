"""Which body collides with which wall, and the nearest points: ``geometry.contacts``."""

from pathlib import Path

import numpy as np
import pytest
import shapely

from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.geometry.contacts import body_contacts, colliding, nearest_points
from wafer_planner_ros.geometry.planar import cross2

PILLAR = Path(__file__).resolve().parents[1] / 'support' / 'cells' / 'pillar.yaml'

SAMPLES = 3000
NEAR = 2e-4
"""m: configurations this close to touching are left out of the shapely comparison (its
circles are polygons, inside the true ones by up to 5e-5 m)."""


def _free_bodies(contacts):
    return [c.body for c in contacts if not c.colliding]


def _colliding(cell, q):
    return {c.body: c.describe() for c in colliding(cell.clearance_model, q)}


def test_a_wafer_pushed_into_the_wall_is_the_only_body_named(default_cell):
    robot = default_cell.robot
    # Heading for the right wall (x = 0.85): the wafer edge reaches x = 0.72 + 0.15 = 0.87,
    # 20 mm into the wall; the links stay clear.
    for solution in robot.arm.inverse((0.72, 0.0), 0.0, robot.limits.position):
        assert _colliding(default_cell, solution.q) == {
            'wafer': 'wafer vs boundary, overlap 20.0 mm'}
        wafer = body_contacts(default_cell.clearance_model, solution.q)[3]
        np.testing.assert_allclose(wafer.wall_point, [0.85, 0.0], atol=1e-9)
        np.testing.assert_allclose(wafer.spine_point, [0.72, 0.0], atol=1e-9)


def test_an_arm_through_the_wall_names_each_body_and_how(default_cell):
    # Straight along -y (between the loadlocks' pockets): the shoulder link ends 30 mm
    # short of the wall, the elbow link crosses it, the wrist link and the wafer lie beyond.
    contacts = body_contacts(default_cell.clearance_model, [-np.pi / 2, 0.0, 0.0])
    assert _free_bodies(contacts) == ['shoulder link']
    assert contacts[0].clearance == pytest.approx(0.03, abs=1e-9)
    assert _colliding(default_cell, [-np.pi / 2, 0.0, 0.0]) == {
        'elbow link': 'elbow link crosses boundary',
        'wrist link': 'wrist link beyond boundary',
        'wafer': 'wafer beyond boundary'}
    assert contacts[1].crossing and not contacts[1].outside
    assert contacts[2].outside and contacts[3].outside
    np.testing.assert_allclose(contacts[1].wall_point, [0.0, -0.45], atol=1e-9)


def test_a_wafer_in_the_pillar_names_the_obstacle():
    cell = Cell.from_yaml(PILLAR)
    robot = cell.robot
    # The pillar's right face is x = -0.78; a wafer centred at x = -0.61 reaches -0.76,
    # one centred at -0.65 reaches -0.80: 20 mm into it.
    clear = robot.arm.inverse((-0.61, 0.0), np.pi, robot.limits.position)
    hit = robot.arm.inverse((-0.65, 0.0), np.pi, robot.limits.position)
    assert clear and hit
    for solution in clear:
        assert _colliding(cell, solution.q) == {}
    for solution in hit:
        assert _colliding(cell, solution.q) == {
            'wafer': 'wafer vs cell.obstacles[0], overlap 20.0 mm'}
        wafer = body_contacts(cell.clearance_model, solution.q)[3]
        assert wafer.owner == 1
        np.testing.assert_allclose(wafer.wall_point, [-0.78, 0.0], atol=1e-9)
    # Its centre inside the pillar: the wafer is inside it, not merely overlapping.
    inside = robot.arm.inverse((-0.86, 0.0), np.pi, robot.limits.position)
    assert _colliding(cell, inside[0].q)['wafer'] == 'wafer inside cell.obstacles[0]'


@pytest.mark.slow
def test_the_colliding_bodies_are_those_shapely_finds(cell):
    """Per body and per outline, on random configurations, against shapely's buffers."""
    rng = np.random.default_rng(5)
    limits = cell.robot.limits.position
    model = cell.clearance_model
    radii = model.radii
    boundary = shapely.Polygon(cell.boundary)
    obstacles = [shapely.Polygon(o) for o in cell.obstacles]
    compared, hits = 0, dict.fromkeys(model.body_names, 0)
    for q in rng.uniform(limits[:, 0], limits[:, 1], (SAMPLES, 3)):
        clearance = model.edge_distances(q)[0].min(axis=1) - radii
        if np.any(np.abs(clearance) < NEAR):
            continue
        points = cell.robot.arm.joint_points(q)
        spines = [shapely.LineString(points[k:k + 2]) for k in range(3)]
        bodies = [s.buffer(r, quad_segs=64) for s, r in zip(spines, radii[:3])]
        bodies.append(shapely.Point(points[3]).buffer(radii[3], quad_segs=64))
        contacts = body_contacts(model, q)
        for k, (body, contact) in enumerate(zip(bodies, contacts)):
            owners = [0] if not boundary.contains(body) else []
            owners += [j + 1 for j, o in enumerate(obstacles) if body.intersects(o)]
            assert contact.colliding == bool(owners), (q, contact.describe())
            if owners:
                hits[contact.body] += 1
                assert contact.owner in owners, (q, contact.describe())
        compared += 1
    assert compared > 0.9 * SAMPLES
    # Each body beyond the shoulder link collides often (the shoulder link reaches no wall
    # in the default cell), so the comparison means something for each.
    assert all(hits[name] > 0.05 * compared for name in model.body_names[1:]), hits


def test_nearest_points_lie_on_both_outlines_at_the_models_distance(cell):
    rng = np.random.default_rng(8)
    limits = cell.robot.limits.position
    model = cell.clearance_model
    for q in rng.uniform(limits[:, 0], limits[:, 1], (300, 3)):
        distances = model.edge_distances(q)[0]
        for contact in body_contacts(model, q):
            start, end = model.edge_start[contact.edge], model.edge_end[contact.edge]
            assert model.edge_owner[contact.edge] == contact.owner
            gap = float(np.hypot(*(contact.spine_point - contact.wall_point)))
            assert gap == pytest.approx(distances[contact.index, contact.edge], abs=1e-12)
            assert contact.clearance == distances[contact.index, contact.edge] - \
                model.radii[contact.index]
            if not contact.outside:  # the nearest outline of all
                assert distances[contact.index, contact.edge] == distances[contact.index].min()
            along = end - start
            assert abs(cross2(along, contact.wall_point - start)) < 1e-12
        free = [c for c in body_contacts(model, q) if not c.colliding]
        if len(free) == 4:  # the configuration is free: its clearance, from the nearest body
            assert min(c.clearance for c in free) == model.clearance(q)[0]


def test_nearest_points_of_crossing_and_parallel_segments():
    p, w = nearest_points([0, 0], [2, 2], [0, 2], [2, 0])
    np.testing.assert_allclose(p, [1, 1])
    np.testing.assert_allclose(w, [1, 1])
    p, w = nearest_points([0, 0], [1, 0], [2, 1], [3, 1])
    np.testing.assert_allclose(p, [1, 0])
    np.testing.assert_allclose(w, [2, 1])
    p, w = nearest_points([0.5, 0.0], [0.5, 0.0], [0, 1], [1, 1])  # a point (the wafer)
    np.testing.assert_allclose(p, [0.5, 0.0])
    np.testing.assert_allclose(w, [0.5, 1.0])


def test_the_clearance_margin_makes_a_near_body_collide(default_cell_file):
    line = '  wafer_acceleration_limit: [0.981, 0.981]'
    text = default_cell_file.read_text()
    assert line in text
    margin_cell = Cell.from_text(text.replace(line, line + '\n  clearance_margin: 0.005'),
                                 'margin.yaml')
    robot = margin_cell.robot
    # The wafer 3 mm from the right wall: free without the margin, within it with it.
    q = robot.arm.inverse((0.697, 0.0), 0.0, robot.limits.position)[0].q
    assert robot.clearance_margin == 0.005
    assert _colliding(margin_cell, q) == {
        'wafer': 'wafer vs boundary, 3.0 mm apart: within the clearance margin of 5.0 mm'}
