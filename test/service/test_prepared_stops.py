"""Stops made ahead of a running move: which moments, in what order, and what a request gets."""

import numpy as np
import pytest

from wafer_planner_ros.service.prepared_stops import AHEAD, EVERY, PreparedStops
from wafer_planner_ros.trajectory.stopping import controlled_stop


@pytest.fixture(scope='module')
def move(station_move):
    return station_move.trajectory


@pytest.fixture
def maker(default_planner, station_move):
    return lambda moment: default_planner.prepare_stop(station_move.trajectory, moment,
                                                       station_move.verification)


def test_the_moments_ahead_of_the_move_are_made_in_order_and_forgotten_once_passed(
        move, default_cell, maker):
    prepared = PreparedStops(move, maker)
    elapsed = 0.5
    made = []
    while (index := prepared.wanted(elapsed, share=1e9)) is not None:  # every moment
        prepared.make(index)
        made.append(index)
    # Every moment after where the move is, up to AHEAD ahead, once and in order.
    first = int(np.floor(elapsed / EVERY)) + 1
    assert made == list(range(first, int(np.floor((elapsed + AHEAD) / EVERY)) + 1))
    # A request a little ahead gets the first moment's stop at or after it, the same stop
    # the core makes there; none before the move got there, or past what was made.
    at = elapsed + 0.031
    ahead = prepared.ahead_of(at, share=1e9)
    moment = ahead.stop.trajectory.timing.states[0, 0]
    assert at <= moment < at + EVERY
    assert ahead.stop.trajectory.duration == controlled_stop(
        move, moment, default_cell.robot).trajectory.duration
    # Verified as it was made, its path's proof the move's.
    assert ahead.stop.timing == 'rest' or (ahead.verification.ok and ahead.verification.on_base)
    assert prepared.ahead_of(elapsed - 0.1, share=1e9) is None
    assert prepared.ahead_of(elapsed + AHEAD + 0.05, share=1e9) is None
    # Moments passed are forgotten; what is ahead is kept.
    prepared.forget_before(elapsed + 0.2)
    assert prepared.ahead_of(at, share=1e9) is None
    assert prepared.ahead_of(elapsed + 0.25, share=1e9) is not None
    assert prepared.count == len([k for k in made if k * EVERY >= elapsed + 0.2])


def test_no_moment_is_wanted_at_or_past_the_move_s_end(move, maker):
    prepared = PreparedStops(move, maker)
    assert prepared.wanted(move.duration) is None
    last = prepared.wanted(move.duration - 0.5 * EVERY)
    assert last is None or last * EVERY < move.duration


def test_stops_that_take_long_to_make_are_made_a_stride_apart_within_a_share_of_a_core(
        move, maker):
    # Stops that took 2.5 times what a share of a core allows between two moments: every
    # third moment is made, and a request is followed at most three moments before it brakes.
    prepared = PreparedStops(move, maker)
    assert prepared.stride(0.5) == 1
    prepared._making = [4, 4 * 2.5 * 0.5 * EVERY]
    assert prepared.stride(0.5) == 3 and prepared.stride(1.0) == 2
    index = prepared.wanted(0.3, 0.5)
    assert index % 3 == 0 and 0.3 < index * EVERY <= 0.3 + 3 * EVERY
    prepared.make(index)
    assert prepared.wanted(0.3, 0.5) == index + 3
    for at in ((index - 2.5) * EVERY, index * EVERY):
        assert prepared.ahead_of(at, 0.5).stop.trajectory.timing.states[0, 0] == index * EVERY
    assert prepared.ahead_of((index - 3.5) * EVERY, 0.5) is None
