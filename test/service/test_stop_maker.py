"""Stops found in a child process: the very stops found in process, put on the caller's move."""

import numpy as np
import pytest

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.service.stop_maker import StopMaker
from wafer_planner_ros.trajectory.stopping import controlled_stop


@pytest.fixture
def maker():
    made = StopMaker()
    yield made
    made.close()


def test_a_stop_found_by_the_child_is_the_one_found_in_process_on_the_caller_s_move(
        maker, default_planner, station_move, default_cell):
    move = station_move.trajectory
    find = maker.finder(move, default_cell.robot)
    for moment in (0.1 * move.duration, 0.4 * move.duration, 0.8 * move.duration):
        found, here = find(moment), controlled_stop(move, moment, default_cell.robot)
        assert found.trajectory.base is move  # the caller's own curve, not a copy
        assert found.timing == here.timing and found.share == here.share
        assert np.array_equal(found.trajectory.timing.states, here.trajectory.timing.states)
        assert np.array_equal(found.trajectory.breaks(), here.trajectory.breaks())
        # A draft only: verified by the caller as any stop.
        prepared = default_planner.prepare_stop(move, moment, station_move.verification,
                                                made=found)
        assert prepared is not None and prepared.verification.ok
    with pytest.raises(PlanningError) as raised:
        find(move.duration + 1.0)
    assert raised.value.code is ErrorCode.OUTSIDE_TRAJECTORY
    assert maker.started == 1


def test_a_child_that_ends_fails_one_stop_and_the_next_starts_another(maker, station_move,
                                                                      default_cell):
    move = station_move.trajectory
    find = maker.finder(move, default_cell.robot)
    find(0.5)
    # Ended while it seemed alive (its end not yet seen): the stop asked of it fails.
    process = maker._child._process
    process.kill()
    process.wait()
    alive = process.poll
    process.poll = lambda: None
    with pytest.raises(RuntimeError, match='the stop maker ended'):
        find(0.6)
    process.poll = alive
    assert find(0.6).trajectory.base is move  # the move handed to the new child again
    assert maker.started == 2
    # Seen ended before a stop is asked: another starts at once, nothing fails.
    maker._child._process.kill()
    maker._child._process.wait()
    assert find(0.7).trajectory.base is move and maker.started == 3
