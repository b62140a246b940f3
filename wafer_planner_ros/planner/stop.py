"""
A controlled stop of a published move, and a move diverted from one, answered like any request.

``stop(planner, trajectory, at, label)`` brings ``trajectory`` to rest from ``at`` seconds
after its start, on its own path, as fast as the planner's limit set allows
(``trajectory.stopping``); the answer starts exactly in the curve's state there (its
velocity and acceleration included) and is verified as every answer is, that start motion
with it. ``divert(planner, trajectory, at, goal, label)`` leaves the move at ``at`` for a
new goal: its controlled stop, then the move from rest where it stops to the goal, as one
trajectory (``chained.Chained``), verified whole; or, faster, one curve from the moving
state to the goal (``continuing``), continuous in acceleration at the join, proven and
verified; its ``metrics`` say which (``divert``: ``'stop-then-move'`` or
``'blended-divert'``) and how long the other took.
"""

from dataclasses import dataclass
import math
import time
from typing import Mapping, Optional

import numpy as np

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner.endpoints import Endpoint
from wafer_planner_ros.planner.result import answer, LENGTH_SAMPLES, path_lengths, PlanResult
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.chained import Chained
from wafer_planner_ros.trajectory.continuing import Continuing, draft, pinned_start
from wafer_planner_ros.trajectory.jerk_profile import JerkProfile
from wafer_planner_ros.trajectory.retimed import Retimed
from wafer_planner_ros.trajectory.stopping import controlled_stop, followed, moving_state
from wafer_planner_ros.trajectory.stopping import rest_of, Stop
from wafer_planner_ros.trajectory.verify import Verification, verify, verify_joined

METHOD = 'controlled-stop'
"""The method a stop's answer names."""
DIVERT = 'stop-then-move'
"""The method a diverted move's answer names: its stop, then the move from rest."""
BLENDED = 'blended-divert'
"""The method a diverted move's answer names when it is one curve from the moving state."""
BLEND_SECONDS = 0.5
"""s: the longest a divert's one curve is sought (less half-way to the request's deadline,
or ``LEAVE_MARGIN`` before the robot passes the moment it leaves the move at)."""
LEAVE_MARGIN = 0.1
"""s before the robot passes the moment a divert leaves its move at by which the search
for one curve ends: left to verify, record and publish the answer."""
FIRST_SPANS = np.array([0.125, 0.125, 0.25, 0.5])
"""The first of a divert's draft's even spans split so (``_blended``): the motion given at
the start is followed closely at first, where the robot brakes or turns fastest."""
STOP_SPANS = 4
"""Spans of the second draft of a divert's one curve over the stop's time (``_blended``)."""


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
           until=None, leaves: Optional[float] = None) -> PlanResult:
    """
    Return the verified move from ``trajectory`` at ``at`` to ``goal`` (the module).

    The controlled stop, then the move from rest to ``goal``, verified as one trajectory;
    then, where that move is a curve of the method's (not through a port), one curve from
    the moving robot's state (``continuing``) fitted to it and optimised for up to
    ``BLEND_SECONDS`` (at most half-way to ``deadline``, and never past ``LEAVE_MARGIN``
    before ``leaves``, the ``time.monotonic()`` instant the robot passes ``at``, if
    known: an answer later than that is of no use), verified: the faster verified one is
    the answer,
    its method saying which (``DIVERT``, ``BLENDED``). ``goal``: a station name or joint
    angles; ``deadline`` and ``until`` as for the planner's moves from rest. Raise
    PlanningError as ``stop`` and the move to the goal do, VERIFICATION_FAILED when
    neither passes.
    """
    begun = time.perf_counter()
    q, qd, qdd = moving_state(trajectory, at)
    halted = stop(planner, trajectory, at, label)
    onward = planner.planned(halted.goal_q, goal, deadline, until)
    chain = Chained([halted.trajectory, onward.trajectory])
    checked = time.perf_counter()
    verification = verify(chain, planner.cell, q, onward.goal_q, moving=(qd, qdd))
    verified = time.perf_counter()
    curve, method, refused = chain, DIVERT, list(verification.problems)
    if isinstance(onward.trajectory, CubicBSpline):
        blended, blend_refused = _blended(planner, chain, onward, (q, qd, qdd), deadline,
                                          leaves)
        refused += blend_refused
        if blended is not None and (not verification.ok or
                                    blended[0].duration < chain.duration):
            curve, verification, method = *blended, BLENDED
    if not verification.ok:
        raise PlanningError(ErrorCode.VERIFICATION_FAILED,
                            f'the move from {label} at {at:.6g} s to {onward.goal.label} '
                            'failed its verification: ' + '; '.join(refused))
    done = time.perf_counter()
    start = Endpoint(f'{label} at {at:.6g} s', ((None, q),))
    timings = {f'onward.{k}': v for k, v in onward.timings_ms.items() if k != 'total'}
    return answer(planner, start, onward.goal, q, onward.goal_q,
                  (None, onward.branches[1]), curve, curve.duration, verification,
                  onward.roadmap_path, onward.path,
                  {'diverted_at': float(at), 'divert': method,
                   'stop_time': halted.cycle_time, 'onward_time': onward.cycle_time,
                   'stop_then_move_time': chain.duration, 'refused': refused},
                  len(curve.control_points) if method == BLENDED else
                  onward.metrics.get('control_points', 0), method=method,
                  timings_ms={'stop': halted.timings_ms['total'], **timings,
                              'verify': 1e3 * (verified - checked),
                              'blend': 1e3 * (done - verified),
                              'total': 1e3 * (done - begun)})


def _blended(planner, chain: Chained, onward: PlanResult, state: tuple, deadline,
             leaves: Optional[float]) -> tuple:
    """
    Return ((curve, verification) or None, what was refused) for ``divert``'s one curve.

    Drafts fitted to the stop-then-move ``chain`` (``continuing.draft``): with
    ``ShapeSettings.min_spans`` even spans, the first split as ``FIRST_SPANS``, then
    with the stop's time in ``STOP_SPANS``
    spans and the onward move's own spans after them; each optimised from the moving
    ``state`` (q, q', q'') to ``onward``'s goal (``CurveMethod.blend``, to beat the
    chain), the first verified returned.
    """
    q, qd, qdd = state
    start = pinned_start(qd, qdd)
    if start is None:
        return None, []
    # Its own time: the budget, if any, was the onward move's.
    until = time.monotonic() + BLEND_SECONDS
    if leaves is not None:
        until = min(until, leaves - LEAVE_MARGIN)
    halted, moving = chain.parts[0].duration, onward.trajectory
    spans = planner.method.shape.min_spans
    refused = []
    even = chain.duration / spans
    for intervals in (np.concatenate([even * FIRST_SPANS, np.full(spans - 1, even)]),
                      np.concatenate([np.full(STOP_SPANS, halted / STOP_SPANS),
                                      moving.intervals])):
        if time.monotonic() >= until:
            break
        fitted = draft(chain, qd, qdd, intervals)
        shaped = planner.method.blend(fitted, (start, None),
                                      chain.duration, until, deadline, proven=False)
        if shaped is None:
            continue
        curve = Continuing(shaped.trajectory.knots, shaped.trajectory.control_points)
        verification = verify(curve, planner.cell, q, onward.goal_q, moving=(qd, qdd))
        if verification.ok:
            return (curve, verification), refused
        refused.append('one curve: ' + '; '.join(verification.problems))
    return None, refused
