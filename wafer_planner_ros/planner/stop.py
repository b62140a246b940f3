"""
A controlled stop of a published move, and a move diverted from one, answered like any request.

``stop(planner, trajectory, at, label)`` brings ``trajectory`` to rest from ``at`` seconds
after its start, on its own path, as fast as the planner's limit set allows
(``trajectory.stopping``); the answer starts exactly in the curve's state there (its
velocity and acceleration included) and is verified as every answer is, that start motion
with it. ``divert(planner, trajectory, at, goal, label)`` leaves the move at ``at`` for a
new goal: for now always its controlled stop, then the move from rest where it stops to
the goal, as one trajectory (``chained.Chained``), verified whole; its ``metrics`` say so
(``divert``: ``'stop-then-move'``).
"""

from dataclasses import dataclass
import math
import time
from typing import Mapping, Optional

import numpy as np

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner.endpoints import Endpoint
from wafer_planner_ros.planner.result import answer, LENGTH_SAMPLES, path_lengths, PlanResult
from wafer_planner_ros.trajectory.chained import Chained
from wafer_planner_ros.trajectory.jerk_profile import JerkProfile
from wafer_planner_ros.trajectory.retimed import Retimed
from wafer_planner_ros.trajectory.stopping import controlled_stop, followed, moving_state
from wafer_planner_ros.trajectory.stopping import rest_of, Stop
from wafer_planner_ros.trajectory.verify import Verification, verify, verify_joined

METHOD = 'controlled-stop'
"""The method a stop's answer names."""
DIVERT = 'stop-then-move'
"""The method a diverted move's answer names: its stop, then the move from rest."""


@dataclass(frozen=True)
class Prepared:
    """A stop made before it is asked for (``prepare``), verified, with its path lengths."""

    stop: Stop
    verification: Optional[Verification]
    """None: not verified (the answer is then verified whole)."""
    lengths: Optional[Mapping[str, float]]


def prepare(planner, trajectory, moment: float, verified: Verification,
            made: Optional[Stop] = None) -> Optional[Prepared]:
    """
    Return the controlled stop of ``trajectory`` from ``moment``, verified; None if it fails.

    ``verified``: the (proven) verification ``trajectory`` passed when it was answered: the
    stop's verification takes the path's proof from it (``verify``'s ``base``). A stop
    that fails it is no draft to answer from (None: a request there finds its own).
    ``made``: the stop found already (elsewhere: ``service.stop_maker``), verified here
    all the same; None: found here. Raise PlanningError as ``controlled_stop`` does (e.g.
    ``AT_REST``).
    """
    if made is None:
        made = controlled_stop(trajectory, moment, planner.cell.robot)
    curve = made.trajectory
    if curve.base is not trajectory:
        raise ValueError('a stop made ahead of another curve')
    q, qd, qdd = moving_state(trajectory, moment)
    end = curve.evaluate([curve.duration])[0]
    verification = verify(curve, planner.cell, q, end, moving=(qd, qdd), base=verified)
    if not verification.ok:
        return None
    return Prepared(made, verification, path_lengths(planner.cell, curve))


def stop(planner, trajectory, at: float, label: str,
         verified: Optional[Verification] = None,
         ahead: Optional[Prepared] = None) -> PlanResult:
    """
    Return the verified controlled stop of ``trajectory`` from ``at`` (the module).

    ``ahead``: a stop of ``trajectory`` made and verified before it was asked for
    (``prepare``, with ``verified``), from a moment no earlier than ``at``
    (``service.prepared_stops``): the answer follows the move to that moment, then brakes
    as it does (``stopping.followed``), and only the part followed and the join are
    checked anew (``verify_joined``); its ``metrics['braking_from']`` is that moment
    (``at`` for a stop found for ``at`` itself).

    ``label``: what the stopped move is called in the answer (e.g. its request id).
    ``verified``: the verification ``trajectory`` passed when it was answered, held since
    (never one read back from a file): the stop keeps its path, so the stop's verification
    checks its limits and ends and takes the path's proof from it (``verify``'s ``base``);
    None (or one without a proven path): the stop is verified whole.

    A stop that fails its verification is not the answer: the next of the stop made ahead
    (followed), the stop found for ``at``, the rest of the move that is (the limits are
    checked more densely while a stop is found, but on other instants than the
    verification's, and a timing at its jerk limit may pass one and not the other by
    1e-6). Raise PlanningError: OUTSIDE_TRAJECTORY or AT_REST
    (``stopping.moving_state``), VERIFICATION_FAILED if none passes.
    """
    begun = time.perf_counter()
    q, qd, qdd = moving_state(trajectory, at)
    base = verified if verified is not None and verified.proven else None
    robot = planner.cell.robot
    tries = [lambda: controlled_stop(trajectory, at, robot), lambda: rest_of(trajectory, at)]
    if ahead is not None:
        tries.insert(0, lambda: followed(ahead.stop, trajectory, at))
    problems, stop_s, verify_s, braking, lengths = [], 0.0, 0.0, float(at), None
    for number, make in enumerate(tries):
        began = time.perf_counter()
        made = make()
        curve = made.trajectory
        end = curve.evaluate([curve.duration])[0]
        checked = time.perf_counter()
        # The path's proof is ``verified``'s only for a stop played along that very curve.
        on_base = base if curve.base is trajectory else None
        # Followed, then as made ahead (the rest of the move from ``at`` is followed, then
        # the rest from the moment made ahead: the same curve): the join is checked.
        joined = number == 0 and ahead is not None and on_base is not None and \
            ahead.verification is not None and made.timing == ahead.stop.timing
        if joined and made is ahead.stop:
            verification = ahead.verification  # made for this very moment
        elif joined:
            coast = float(ahead.stop.trajectory.timing.states[0, 0]) - float(at)
            verification = verify_joined(curve, planner.cell, q, end, (qd, qdd), on_base,
                                         coast, (ahead.stop.trajectory, ahead.verification))
        else:
            verification = verify(curve, planner.cell, q, end, moving=(qd, qdd), base=on_base)
        stop_s, verify_s = stop_s + checked - began, verify_s + time.perf_counter() - checked
        if verification.ok:
            if joined:
                braking = float(ahead.stop.trajectory.timing.states[0, 0])
                lengths = _joined_lengths(planner.cell, trajectory, at, braking, ahead)
            break
        problems.append(f'{made.timing}: ' + '; '.join(verification.problems))
    else:
        raise PlanningError(ErrorCode.VERIFICATION_FAILED,
                            f'the stop of {label} at {at:.6g} s failed its verification: '
                            + ' | '.join(problems))
    done = time.perf_counter()
    start = Endpoint(f'{label} at {at:.6g} s', ((None, q),))
    goal = Endpoint(f'{label} stopped', ((None, end),))
    return answer(planner, start, goal, q, end, (None, None), curve, curve.duration,
                  verification, q[None], q[None], {'stopped_at': float(at),
                                                   'braking_from': braking,
                                                   'share': made.share,
                                                   'timing': made.timing,
                                                   'refused': problems},
                  0, method=METHOD, lengths=lengths,
                  timings_ms={'stop': 1e3 * stop_s, 'verify': 1e3 * verify_s,
                              'total': 1e3 * (done - begun)})


def _joined_lengths(cell, trajectory, at: float, moment: float, ahead: Prepared) -> dict:
    """
    Return the path lengths of the move followed from ``at`` to ``moment``, then ``ahead``.

    The stretch followed is sampled as densely as ``ahead``'s lengths were (at least).
    """
    rest = ahead.stop.trajectory.duration
    samples = max(2, int(math.ceil((LENGTH_SAMPLES - 1) * (moment - at) / rest)) + 1)
    stretch = Retimed(trajectory, JerkProfile(np.array([0.0, moment - at]), np.zeros(1),
                                              np.array([[at, 1.0, 0.0], [moment, 1.0, 0.0]])))
    followed_ = path_lengths(cell, stretch, samples)
    return {name: followed_[name] + ahead.lengths[name] for name in followed_}


def divert(planner, trajectory, at: float, goal, label: str, deadline=None,
           until=None) -> PlanResult:
    """
    Return the verified move from ``trajectory`` at ``at`` to ``goal`` (the module).

    ``goal``: a station name or joint angles; ``deadline`` and ``until`` as for the
    planner's moves from rest. Raise PlanningError as ``stop`` and the move to the goal do.
    """
    begun = time.perf_counter()
    q, qd, qdd = moving_state(trajectory, at)
    halted = stop(planner, trajectory, at, label)
    rested = halted.goal_q
    onward = planner.planned(rested, goal, deadline, until)
    curve = Chained([halted.trajectory, onward.trajectory])
    checked = time.perf_counter()
    verification = verify(curve, planner.cell, q, onward.goal_q, moving=(qd, qdd))
    if not verification.ok:
        raise PlanningError(ErrorCode.VERIFICATION_FAILED,
                            f'the move from {label} at {at:.6g} s to {onward.goal.label} '
                            'failed its verification: ' + '; '.join(verification.problems))
    done = time.perf_counter()
    start = Endpoint(f'{label} at {at:.6g} s', ((None, q),))
    timings = {f'onward.{k}': v for k, v in onward.timings_ms.items() if k != 'total'}
    return answer(planner, start, onward.goal, q, onward.goal_q,
                  (None, onward.branches[1]), curve, curve.duration, verification,
                  onward.roadmap_path, onward.path,
                  {'diverted_at': float(at), 'divert': DIVERT,
                   'stop_time': halted.cycle_time, 'onward_time': onward.cycle_time},
                  onward.metrics.get('control_points', 0), method=DIVERT,
                  timings_ms={'stop': halted.timings_ms['total'], **timings,
                              'verify': 1e3 * (done - checked),
                              'total': 1e3 * (done - begun)})
