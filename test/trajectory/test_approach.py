"""The closest approach of a motion to the walls: ``trajectory.approach``."""

import numpy as np
import pytest

from wafer_planner_ros.planner import Planner
from wafer_planner_ros.trajectory.approach import closest_approach, densified, on_curve
from wafer_planner_ros.trajectory.approach import on_samples

PAIRS = [('loadport2', 'loadlock1'), ('loadlock1', 'loadport3'), ('loadport1', 'loadlock2')]


@pytest.fixture(scope='module')
def plans(default_cell, default_roadmap):
    """Return the corridor-curve plans of ``PAIRS`` (milliseconds each)."""
    planner = Planner(default_cell, default_roadmap)
    return [planner.plan(*pair) for pair in PAIRS]


def test_on_the_curve_it_is_the_verified_minimum_clearance(plans, default_cell):
    model = default_cell.clearance_model
    for result in plans:
        approach = on_curve(model, result.trajectory)
        assert approach.distance == result.min_clearance
        assert 0.0 <= approach.time <= result.cycle_time
        np.testing.assert_array_equal(approach.q, result.trajectory.evaluate([approach.time])[0])
        assert model.clearance(approach.q)[0] == approach.contact.clearance
    # loadport2 -> loadlock1 passes 2.1 mm from a wall with the wafer.
    first = on_curve(model, plans[0].trajectory)
    assert first.distance * 1000 == pytest.approx(2.13, abs=0.05)
    assert (first.contact.body, first.contact.obstacle) == ('wafer', 'boundary')


def test_between_recorded_samples_it_is_found_as_on_the_curve(plans, default_cell):
    model = default_cell.clearance_model
    missed = []
    for result in plans:
        exact = on_curve(model, result.trajectory)
        for period in (0.01, 0.2):  # the node's default sample period, and a long one
            times, q, qd, qdd = result.trajectory.samples(period)
            sampled = on_samples(model, times, q, qd, qdd)
            assert sampled.distance == pytest.approx(exact.distance, abs=2e-7)
            assert sampled.time == pytest.approx(exact.time, abs=2e-3)
            assert sampled.contact.body == exact.contact.body
            missed.append(closest_approach(model, times, q).distance - exact.distance)
    # The samples alone would miss it: by 2.1 mm on loadport1 -> loadlock2 every 0.2 s.
    assert max(missed) > 1e-3


def test_densified_motion_follows_the_curve_and_is_fine_enough(plans):
    result = plans[1]
    times, q = densified(result.times, result.positions, result.velocities,
                         result.accelerations)
    assert times[0] == 0.0 and times[-1] == result.cycle_time and np.all(np.diff(times) > 0)
    assert np.abs(np.diff(q, axis=0)).max() <= 1.05e-3  # rad between configurations
    np.testing.assert_allclose(q, result.trajectory.evaluate(times), rtol=0, atol=2e-6)
