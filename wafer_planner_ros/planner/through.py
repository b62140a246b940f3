"""
A move through a port: straight out of one port, a transfer, straight into the other.

Per elbow-branch combination: straight out of the start's port along its axis
(``moves.channel``), the transfer between the two port mouths, straight into the goal's
port. The transfer is first planned from rest to rest (``Planner.transfer``: a move between
the mouths, planned once per planner without a budget), which makes the move that stops at
the mouths (``moves.through.compose``); when blending, the curve method then optimises the
transfer with each mouth a free end (``CurveMethod.blend``: the mouth speeds chosen with the
transfer, the ways through the ports timed to meet them), and the faster verified move is
kept. Combinations are taken fastest first by the joints' own shortest motion between the
mouths plus the ways at their fastest, and given up when that cannot beat the best so far.
Every answer is verified as a whole (``verify``).
"""

from dataclasses import replace
import logging
import time
from typing import Mapping, Optional

import numpy as np

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.moves.channel import channel_bounds
from wafer_planner_ros.moves.through import compose, free_end, PortMove
from wafer_planner_ros.moves.timing import profile
from wafer_planner_ros.planner.endpoints import Endpoint, mouth_label
from wafer_planner_ros.planner.result import answer, PlanResult
from wafer_planner_ros.planner.stages import check_deadline, Clock, stage_totals, with_total
from wafer_planner_ros.trajectory.shape_problem import FreeEnd
from wafer_planner_ros.trajectory.stopwatch import collecting
from wafer_planner_ros.trajectory.verify import verify

logger = logging.getLogger(__name__)

LEGS_SHARE = 0.75
"""Of the time to a budgeted request's deadline, the share a move through a port may spend
on its transfer: the rest verifies and answers."""
MAX_WAY_TIME = 30.0
"""s: a way through a port that takes longer from rest to rest is refused (NO_PATH)."""


def through(planner, a: Endpoint, b: Endpoint, deadline: Optional[float],
            until: Optional[float], begun: float, blend: bool) -> PlanResult:
    """
    Return the fastest verified move through a port between two resolved ends.

    ``blend``: optimise the transfer into the ways through the ports (else stop at each
    mouth). ``until``, ``begun`` as for ``candidates.search``.
    """
    stage_ms = stage_totals()
    clock = Clock(stage_ms)
    combinations, failure = _combinations(planner, a, b)
    clock.lap('corridor')
    best, tried = None, 0
    # Within a budget, the transfer (planned, unless kept from an earlier answer, and
    # blended) may take up to LEGS_SHARE of the time to the deadline: the budget alone
    # leaves it slower than the move stopping at the mouths unbudgeted. Once one move is
    # verified and that time is spent, only the combinations whose transfer is kept
    # are tried.
    left = None if deadline is None else max(deadline - time.monotonic(), 0.0)
    legs_until = until if until is None or left is None else \
        max(until, time.monotonic() + LEGS_SHARE * left)
    for fastest, i, j, ways, mouths in sorted(combinations, key=lambda c: c[0]):
        check_deadline(deadline)
        if best is not None and fastest >= best.cycle_time:
            continue
        (elbow_a, _), (elbow_b, _) = a.configs[i], b.configs[j]
        if best is not None and legs_until is not None and \
                time.monotonic() >= legs_until and not planner.holds_transfer(
                    mouths, (elbow_a, elbow_b)):
            continue
        if np.array_equal(*mouths):
            # Only out of a port to its mouth, or only in: the way alone.
            result = port_answer(planner, a, b, i, j, None, compose(None, *ways), {}, ())
            if result is None:
                failure = failure or _failed(a, b)
            elif best is None or result.cycle_time < best.cycle_time:
                best, tried = result, tried + 1
            continue
        ends = [Endpoint(end.label if way is None else mouth_label(end, role),
                         ((elbow, mouth),))
                for end, role, way, elbow, mouth in zip(
                    (a, b), ('start', 'goal'), ways, (elbow_a, elbow_b), mouths)]
        try:
            transfer = planner.transfer(*ends, deadline, legs_until)
            stop = compose(transfer.trajectory, *ways)
        except PlanningError as exc:
            logger.debug('branches %s -> %s: no transfer: %s', elbow_a, elbow_b, exc)
            failure = failure or exc
            continue
        tried += 1
        moves = [(stop, transfer.metrics, transfer.warnings)]
        if blend:
            clock.lap('stopping')
            with collecting(stage_ms):
                shaped = planner.method.blend(
                    transfer.trajectory, [None if way is None else way_end(planner, way)
                                          for way in ways],
                    None if best is None else best.cycle_time, legs_until, deadline)
            clock.lap('optimise')
            try:
                if shaped is not None:
                    moves.insert(0, (compose(shaped.trajectory, *ways),
                                     dict(transfer.metrics, **shaped.metrics),
                                     transfer.warnings + shaped.warnings))
            except ValueError as exc:  # a mouth state no way through its port meets
                logger.warning('the move %s -> %s, blended, is left: %s', a.label,
                               b.label, exc)
        # Fastest first: stopping can be the faster where a mouth is near a fold.
        for move, metrics, warnings in sorted(moves, key=lambda m: m[0].duration):
            if best is not None and move.duration >= best.cycle_time:
                continue
            result = port_answer(planner, a, b, i, j, transfer, move, metrics, warnings)
            clock.lap('verify')
            if result is None:
                failure = failure or _failed(a, b)
                continue
            best = result
            break
    if best is None:
        raise failure or PlanningError(ErrorCode.NO_PATH,
                                       f'no move from {a.label} to {b.label}')
    return replace(best, metrics=dict(best.metrics, candidates=len(combinations),
                                      given_up=len(combinations) - tried),
                   timings_ms=with_total(stage_ms, begun))


def way(planner, end: Endpoint, k: int) -> Optional[tuple]:
    """
    Return (Channel, Bounds) of configuration ``k``'s way out of its port, or None.

    The bounds are the planner's limit set's along it (``channel_bounds``), kept per
    channel; a way that has none, or takes over ``MAX_WAY_TIME``, raises NO_PATH.
    """
    channel = end.channel(k)
    if channel is None:
        return None
    key = (channel.inside.tobytes(), channel.mouth.tobytes(), channel.length)
    found = planner.legs.cached('bounds', key, lambda: _bounds(planner, channel))
    if isinstance(found, str):
        raise PlanningError(ErrorCode.NO_PATH, f'{end.label}: {found}')
    return channel, found


def way_end(planner, way: tuple) -> FreeEnd:
    """Return a way through a port as the transfer's free end (kept per channel)."""
    channel, bounds = way
    key = (channel.inside.tobytes(), channel.mouth.tobytes(), bounds)
    return planner.legs.cached('ends', key, lambda: free_end(channel, bounds))


def port_answer(planner, a: Endpoint, b: Endpoint, i: int, j: int,
                transfer: Optional[PlanResult], move: PortMove, metrics: Mapping,
                warnings) -> Optional[PlanResult]:
    """
    Return a move through a port from ``a`` to ``b`` as a verified answer, else None.

    ``transfer``: the planned transfer the move's was made from (None: a way alone).
    """
    qa, qb = a.configs[i][1], b.configs[j][1]
    checked = verify(move, planner.cell, qa, qb)
    if not checked.ok:
        logger.warning('the move %s -> %s failed verification: %s', a.label, b.label,
                       '; '.join(checked.problems))
        return None
    roadmap_path = np.empty((0, 3)) if transfer is None else transfer.roadmap_path
    path = np.stack([qa, qb]) if transfer is None else np.concatenate(
        [qa[None]] * (move.out is not None) + [transfer.path]
        + [qb[None]] * (move.into is not None))
    speeds = [0.0 if w is None else w.profile.end_speed for w in (move.out, move.into)]
    braking = [0.0 if w is None else -w.profile.end_acceleration
               for w in (move.out, move.into)]
    stops = sum(w is not None and w.profile.end_speed == 0.0 for w in (move.out, move.into))
    return answer(
        planner, a, b, qa, qb, (a.configs[i][0], b.configs[j][0]), move,
        move.in_port_time + (0.0 if transfer is None else transfer.initial_cycle_time),
        checked, roadmap_path, path,
        dict(metrics, stops=stops, start_mouth_speed=speeds[0], goal_mouth_speed=speeds[1],
             start_mouth_braking=braking[0], goal_mouth_braking=braking[1],
             in_port_time=move.in_port_time, transfer_time=move.duration - move.in_port_time),
        0 if move.transfer is None else len(move.transfer.control_points), warnings)


def _combinations(planner, a: Endpoint, b: Endpoint) -> tuple:
    """Return each elbow-branch combination with a way (fastest, i, j, ways, mouths)."""
    combinations, failure = [], None
    for i, (elbow_a, qa) in enumerate(a.configs):
        for j, (elbow_b, qb) in enumerate(b.configs):
            if np.array_equal(qa, qb):
                raise PlanningError(ErrorCode.INVALID_REQUEST,
                                    f'start and goal are the same configuration '
                                    f'{qa.tolist()}')
            try:
                ways = [way(planner, a, i), way(planner, b, j)]
            except PlanningError as exc:
                failure = failure or exc
                continue
            mouths = [q if w is None else w[0].mouth for q, w in zip((qa, qb), ways)]
            fastest = float(planner.cell.robot.limits.shortest_motion(
                mouths[1] - mouths[0]).max()) + sum(
                    way_end(planner, w).least_time for w in ways if w is not None)
            combinations.append((fastest, i, j, ways, mouths))
    return combinations, failure


def _bounds(planner, channel):
    """Return the bounds along a channel at the planner's limits, or why it has none."""
    try:
        found = channel_bounds(channel, planner.cell.robot)
    except ValueError as exc:
        return str(exc)
    took = profile(channel.length, 0.0, found.at(0.0, 0.0)).duration
    if took > MAX_WAY_TIME:
        return (f'its straight way out of the port takes {took:.1f} s at the '
                f'{planner.load} limits (over {MAX_WAY_TIME:g} s: the arm is nearly '
                'folded or stretched along it)')
    return found


def _failed(a: Endpoint, b: Endpoint) -> PlanningError:
    """Return the failure of a move through a port that failed verification."""
    return PlanningError(ErrorCode.VERIFICATION_FAILED,
                         f'the move {a.label} -> {b.label} failed verification')
