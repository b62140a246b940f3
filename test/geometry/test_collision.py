"""The vectorised clearance model against the python-fcl reference."""

import numpy as np
import pytest

SAMPLES = 100_000


@pytest.fixture(scope='module')
def fcl_agreement(cell):
    """Random configurations with both models' verdicts and clearances."""
    rng = np.random.default_rng(11)
    limits = cell.robot.limits.position
    q = rng.uniform(limits[:, 0], limits[:, 1], (SAMPLES, 3))
    model, reference = cell.clearance_model, cell.fcl_model()
    bulk = model.clearance(q)
    fcl_hit = np.array([reference.in_collision(x) for x in q])
    free = ~fcl_hit
    fcl_clearance = np.full(SAMPLES, np.nan)
    fcl_clearance[free] = [reference.clearance(x) for x in q[free]]
    return q, bulk, fcl_hit, fcl_clearance


@pytest.mark.slow
def test_bulk_collision_verdict_agrees_with_fcl(fcl_agreement):
    q, bulk, fcl_hit, _ = fcl_agreement
    disagree = np.nonzero((bulk <= 0.0) != fcl_hit)[0]
    assert disagree.size == 0, f'{disagree.size} disagreements, e.g. q={q[disagree[0]]}'
    # Both verdicts occur in large numbers, so the comparison means something.
    assert 0.1 < fcl_hit.mean() < 0.9


@pytest.mark.slow
def test_bulk_clearance_agrees_with_fcl_within_a_micrometre(fcl_agreement):
    q, bulk, fcl_hit, fcl_clearance = fcl_agreement
    free = ~fcl_hit
    error = np.abs(bulk[free] - fcl_clearance[free])
    assert error.max() <= 1e-6, f'worst at q={q[free][np.argmax(error)]}: {error.max()} m'


def test_batched_fcl_check_agrees_with_the_fcl_manager(cell):
    rng = np.random.default_rng(12)
    limits = cell.robot.limits.position
    q = rng.uniform(limits[:, 0], limits[:, 1], (5000, 3))
    reference = cell.fcl_model()
    single = np.array([reference.in_collision(x) for x in q])
    assert np.array_equal(reference.in_collision_many(q), single)


def test_contact_names_the_touching_body_and_obstacle(default_cell):
    model = default_cell.clearance_model
    # Arm straight down: the elbow link crosses the wall at y = -0.45.
    contact = model.contact(np.array([-np.pi / 2, 0.0, 0.0]))
    assert (contact.body, contact.obstacle, contact.crossing) == ('elbow link', 'boundary', True)
    # Wafer pushed 2 cm into the right wall, spine inside: a measured overlap.
    q = default_cell.robot.arm.inverse([0.72, 0.0], 0.0,
                                       default_cell.robot.limits.position)[0].q
    contact = model.contact(q)
    assert (contact.body, contact.obstacle, contact.crossing) == ('wafer', 'boundary', False)
    assert np.isclose(contact.clearance, -0.02)
    free = model.contact(np.array([0.0, np.pi, 0.0]))  # folded along +x
    assert free.clearance > 0
    assert np.isclose(free.clearance, model.clearance(np.array([0.0, np.pi, 0.0]))[0])


def test_body_clearance_of_a_known_pose(default_cell):
    # Shoulder pointing along -y, elbow folded back up: the shoulder capsule's far end is
    # 0.36 + 0.06 m from the base, 0.03 m from the wall at y = -0.45.
    model = default_cell.clearance_model
    d = model.body_clearance(np.array([-np.pi / 2, np.pi, 0.0]))[0]
    assert np.isclose(d[0], 0.45 - 0.42)
