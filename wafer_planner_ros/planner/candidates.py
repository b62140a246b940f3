"""
The search over a request's elbow-branch combinations, for the fastest verified curve.

Every combination is taken up to its curve method's draft (roadmap path, corridor, spline:
``prepare``), then finished most promising first. A combination is given up before it is
optimised when even its joints' fastest rest-to-rest motions
(``JointLimits.shortest_motion``) take longer than the best so far, part-way when its
optimisation shows it cannot win (the methods' ``give_up_above``), and unfinished once a
time budget is spent and one is finished. Only the answer is verified, shortest first; one
that fails falls back to the curve its method started from, then to the next combination,
and when every finished one fails, those given up are finished after all. Each combination
is drafted with the planner's kept optimum nearest its ends, if any (``optima``), and each
verified answer the curve method calls an optimum is kept there.
"""

from dataclasses import dataclass
import logging
import time
from typing import Optional, Tuple

import numpy as np

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner.endpoints import Endpoint
from wafer_planner_ros.planner.legs import leg_key
from wafer_planner_ros.planner.result import answer, PlanResult
from wafer_planner_ros.planner.stages import check_deadline, Clock, stage_totals, with_total
from wafer_planner_ros.roadmap.search import find_path
from wafer_planner_ros.roadmap.shortcut import shortcut
from wafer_planner_ros.trajectory.corridor import build_corridor, simplify
from wafer_planner_ros.trajectory.methods import Draft, Shaped
from wafer_planner_ros.trajectory.stopwatch import collecting
from wafer_planner_ros.trajectory.verify import Verification, verify

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Prepared:
    """One elbow-branch combination up to its curve method's draft."""

    a: Endpoint
    b: Endpoint
    qa: np.ndarray
    qb: np.ndarray
    branches: Tuple[Optional[int], Optional[int]]
    roadmap_path: np.ndarray
    path: np.ndarray
    control_points: int
    """How many control points the corridor placed."""
    draft: Draft
    fastest: float
    """s: no motion between the two configurations is faster (the joint limits alone)."""


@dataclass(frozen=True, eq=False)
class Candidate:
    """A finished combination, before verification."""

    pair: Prepared
    shaped: Shaped

    def fallback(self) -> Optional['Candidate']:
        """Return the combination with the curve its method started from, if it has one."""
        make = self.shaped.fallback
        return None if make is None else Candidate(self.pair, make())


def search(planner, a: Endpoint, b: Endpoint, deadline: Optional[float],
           until: Optional[float], begun: float) -> PlanResult:
    """
    Return the fastest verified answer between two resolved ends, neither inside a port.

    ``until``: the time budget's end (``time.monotonic``), None for none; ``begun``: when
    the request began (``time.perf_counter``). An answer planned without a budget is kept
    as a transfer between its ends, with the slower combinations it finished as drafts
    (``legs``). Raise the first PlanningError met when no combination is answered.
    """
    stage_ms = stage_totals()
    prepared, failure = _prepare_all(planner, a, b, deadline, stage_ms, until is not None)
    candidates, given_up = _finish_all(planner, prepared, deadline, until, stage_ms)
    while candidates:
        counts = {'candidates': len(prepared), 'given_up': len(given_up)}
        answered, failure = _first_verified(planner, candidates, counts, deadline, stage_ms,
                                            begun, failure, keep=until is None)
        if answered is not None:
            return answered
        # Every faster one failed verification: finish those given up after all.
        candidates = [c for c in (finish(planner, pair, None, stage_ms, until, deadline)
                                  for pair in given_up) if c is not None]
        given_up = []
    raise failure


def prepare(planner, a: Endpoint, b: Endpoint, qa, qb, branches, stage_ms,
            seeded: bool = False) -> Prepared:
    """
    Return the path, corridor and the method's draft between two configurations.

    ``seeded``: drafted with the kept optimum nearest the two (within a time budget only:
    without one, an answer never depends on what was asked before).
    """
    model = planner.cell.motion_model  # the port margins too: the corridor keeps them
    lipschitz = model.lipschitz
    route = find_path(planner.roadmap, model, lipschitz, qa, qb)
    stage_ms['connect'] += route.connect_ms
    stage_ms['search'] += route.search_ms
    if route.path is None:
        raise PlanningError(ErrorCode.NO_PATH,
                            f'no path from {a.label} to {b.label} in the roadmap '
                            f'({planner.roadmap.node_count} nodes): connect more nodes or '
                            'check the cell')
    clock = Clock(stage_ms)
    settings = planner.settings
    roadmap_path = simplify(route.path)
    path = shortcut(roadmap_path, model, lipschitz) if settings.shortcut else roadmap_path
    corridor = build_corridor(path, model.body_clearance(path), lipschitz,
                              per_body=settings.per_body_boxes, extra=settings.extra_points)
    clock.lap('corridor')
    draft = planner.method.draft(corridor, planner.optima.nearest(qa, qb) if seeded else None)
    clock.lap('spline')
    fastest = float(planner.cell.robot.limits.shortest_motion(qb - qa).max())
    return Prepared(a, b, qa, qb, branches, roadmap_path, path, len(corridor.control_points),
                    draft, fastest)


def finish(planner, pair: Prepared, give_up_above, stage_ms, until=None,
           deadline=None) -> Optional[Candidate]:
    """Return the finished curve, not yet verified; None if it cannot win."""
    clock = Clock(stage_ms)
    with collecting(stage_ms):  # the optimisation's parts (``stopwatch.PARTS``)
        shaped = planner.method.finish(pair.draft, give_up_above, until, deadline)
    clock.lap('optimise')
    return None if shaped is None else Candidate(pair, shaped)


def verified(planner, candidate: Candidate, stage_ms) -> Verification:
    """Return the dense check of a candidate; raise VERIFICATION_FAILED if it fails."""
    clock = Clock(stage_ms)
    pair = candidate.pair
    checked = verify(candidate.shaped.trajectory, planner.cell, pair.qa, pair.qb)
    clock.lap('verify')
    if not checked.ok:
        raise PlanningError(ErrorCode.VERIFICATION_FAILED,
                            f'the trajectory {pair.a.label} -> {pair.b.label} '
                            'failed verification: ' + '; '.join(checked.problems))
    return checked


def result(planner, candidate: Candidate, checked: Verification, counts: dict,
           timings_ms: dict) -> PlanResult:
    """Return the verified candidate as an answer, sampled and measured."""
    pair, shaped = candidate.pair, candidate.shaped
    return answer(planner, pair.a, pair.b, pair.qa, pair.qb, pair.branches,
                  shaped.trajectory, shaped.initial_cycle_time, checked, pair.roadmap_path,
                  pair.path, dict(shaped.metrics, stops=0), pair.control_points,
                  shaped.warnings, timings_ms, extra=counts)


def drafted(planner, candidate: Candidate, counts: dict) -> Optional[PlanResult]:
    """
    Return a kept draft verified as an answer, and keep it; None if it fails verification.

    A draft is a slower combination an answer finished but did not verify (``legs``): a
    move through a port verifies it when it first asks for that transfer.
    """
    begun = time.perf_counter()
    stage_ms = stage_totals()
    try:
        checked = verified(planner, candidate, stage_ms)
    except PlanningError as exc:
        logger.debug('a kept combination is planned again: %s', exc)
        return None
    answered = result(planner, candidate, checked, counts, with_total(stage_ms, begun))
    planner.keep(answered)
    return answered


def _prepare_all(planner, a: Endpoint, b: Endpoint, deadline, stage_ms,
                 seeded: bool) -> tuple:
    """Return every combination prepared (``prepare``), and the first reason one could not be."""
    prepared, failure = [], None
    for elbow_a, qa in a.configs:
        for elbow_b, qb in b.configs:
            if np.array_equal(qa, qb):
                raise PlanningError(ErrorCode.INVALID_REQUEST,
                                    f'start and goal are the same configuration '
                                    f'{qa.tolist()}')
            check_deadline(deadline)
            try:
                prepared.append(prepare(planner, a, b, qa, qb, (elbow_a, elbow_b), stage_ms,
                                        seeded))
            except PlanningError as exc:
                logger.debug('branches %s -> %s dropped: %s', elbow_a, elbow_b, exc)
                failure = failure or exc
    return prepared, failure


def _finish_all(planner, prepared: list, deadline, until, stage_ms) -> tuple:
    """Return the combinations finished, and those given up (unfinished or beaten)."""
    # Most promising first (the method's starting point), so that a combination whose
    # optimisation shows it cannot beat the best so far is given up early.
    candidates, given_up = [], []
    for pair in sorted(prepared, key=lambda p: p.draft.estimate):
        check_deadline(deadline)
        best = min((c.shaped.trajectory.duration for c in candidates), default=None)
        if best is not None and pair.fastest >= best:
            logger.debug('branches %s take at least %.3f s, the best so far %.3f s; '
                         'given up', pair.branches, pair.fastest, best)
            given_up.append(pair)
            continue
        if best is not None and until is not None and time.monotonic() >= until:
            logger.debug('branches %s not optimised: the time budget is spent', pair.branches)
            given_up.append(pair)
            continue
        candidate = finish(planner, pair, best, stage_ms, until, deadline)
        if candidate is None:
            logger.debug('branches %s cannot beat %.3f s; given up', pair.branches, best)
            given_up.append(pair)
        else:
            candidates.append(candidate)
    return candidates, given_up


def _first_verified(planner, candidates: list, counts: dict, deadline, stage_ms,
                    begun: float, failure, keep: bool) -> tuple:
    """
    Return (the shortest candidate that passes verification as an answer, the failure).

    One that fails is tried with the curve its method started from. With ``keep`` the
    answer is kept as a transfer between its ends, its slower rivals as drafts
    (``legs``). (None, the first failure) when none passes.
    """
    # Shortest cycle first; only what is returned needs verifying.
    ordered = sorted(candidates, key=lambda c: c.shaped.trajectory.duration)
    for k, candidate in enumerate(ordered):
        check_deadline(deadline)
        try:
            checked = verified(planner, candidate, stage_ms)
        except PlanningError as exc:
            candidate = candidate.fallback()
            logger.warning('%s; trying %s', exc, 'the curve it started from'
                           if candidate else 'the next branch combination')
            failure = failure or exc
            try:
                checked = verified(planner, candidate, stage_ms) if candidate else None
            except PlanningError:
                checked = None
            if checked is None:
                continue
        answered = result(planner, candidate, checked, counts, with_total(stage_ms, begun))
        if candidate.shaped.optimum:  # a draft for requests near it
            planner.optima.add(answered.start_q, answered.goal_q, answered.trajectory)
        if keep:  # a transfer between port mouths, should one ask for it
            planner.keep(answered)
            for other in ordered[k + 1:]:  # the slower ones, not verified (``legs``)
                planner.legs.keep('drafts', leg_key(other.pair.qa, other.pair.qb,
                                                    other.pair.branches), (other, counts))
        return answered, failure
    return None, failure
