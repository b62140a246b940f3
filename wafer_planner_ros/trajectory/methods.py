"""
Ways to shape and time a curve through a safe corridor.

The planner gives a method the corridor of every elbow-branch combination and asks for a
``Draft`` (its ``estimate`` orders the combinations), then finishes the drafts most
promising first, telling each the cycle time it need not beat. A finished curve that fails
verification is replaced by its ``fallback`` when it has one. A method returns a curve
(any ``Trajectory``) with its own figures; the planner verifies it. Methods are named by
``PlannerSettings.method``; ``METHODS`` lists them.
"""

from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
import math
import time
from typing import Callable, ClassVar, Mapping, Optional, Tuple

from wafer_planner_ros.trajectory import stopwatch
from wafer_planner_ros.trajectory.bspline import CubicBSpline, DEGREE
from wafer_planner_ros.trajectory.coarse import coarse_start
from wafer_planner_ros.trajectory.corridor import Corridor
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.proof import prove
from wafer_planner_ros.trajectory.shape import optimise_shape, Shaping
from wafer_planner_ros.trajectory.shape_problem import breaks_keep_outs
from wafer_planner_ros.trajectory.timing import optimise
from wafer_planner_ros.trajectory.timing_problem import scaled_start, TimingProblem
from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings
from wafer_planner_ros.trajectory.warm import moved_to

PLAIN_ROUNDS = 2
"""Rounds of the coarse stage under the port rule alone, where its start breaks a keep-out
round another port's mouth (``WholeCurve.finish``): where that stage wins it proves its
curve in one or two; where the keep-out is needed it proves nothing, and more rounds would
only cost."""


@dataclass(frozen=True, eq=False)
class Draft:
    """A method's starting point for one corridor."""

    estimate: float
    """s: the cycle time of the starting point (what finishing it improves on)."""
    work: object
    """The method's own state, handed back to ``finish``."""


@dataclass(frozen=True, eq=False)
class Shaped:
    """A finished curve, not yet verified."""

    trajectory: Trajectory
    initial_cycle_time: float
    """s: the cycle time the method started from."""
    metrics: Mapping = field(default_factory=dict)
    """The method's own figures (solver iterations and the like)."""
    warnings: Tuple[str, ...] = ()
    fallback: Optional[Callable[[], 'Shaped']] = None
    """Makes what to return instead if this curve fails verification (the corridor curve),
    if anything: called only then."""
    optimum: bool = False
    """Whether the curve is an optimum worth starting nearby requests from, once verified
    (``planner.optima``): the whole-curve optimisation's, not the corridor curve."""


class CurveMethod(ABC):
    """A way to shape and time a curve through a corridor for one cell's robot."""

    name: ClassVar[str]

    def __init__(self, cell, settings: TimingSettings, shape: ShapeSettings = ShapeSettings()):
        """Keep the cell and the optimisers' tuning."""
        self.cell = cell
        self.settings = settings
        self.shape = shape

    @abstractmethod
    def draft(self, corridor: Corridor, seed: Optional[CubicBSpline] = None) -> Draft:
        """
        Return the starting point for a corridor.

        ``seed``: a verified optimum between configurations near the corridor's ends
        (``planner.optima``), which a method may start from instead (not proven for these
        ends: never returned as it is); None: none.
        """

    @abstractmethod
    def finish(self, draft: Draft, give_up_above: Optional[float] = None,
               until: Optional[float] = None,
               deadline: Optional[float] = None) -> Optional[Shaped]:
        """
        Return the finished curve; None once it shows it cannot beat ``give_up_above`` s.

        ``until``: a ``time.monotonic()`` instant by which a method that improves a curve
        step by step returns the best it has (the time budget). ``deadline``: the request's
        (``time.monotonic()``), which no work may reach: what a method does beyond
        ``until`` stops half-way to it, leaving time to verify and answer.
        """

    def blend(self, transfer: CubicBSpline, ends, give_up_above: Optional[float] = None,
              until: Optional[float] = None, deadline: Optional[float] = None,
              proven: bool = True) -> Optional[Shaped]:
        """
        Return ``transfer`` made to move on at its free ends, or None (see ``ShapeProblem``).

        ``ends``: the start's and the goal's ``FreeEnd`` (None: at rest there). ``transfer``
        is at rest at both ends, proven and within every limit; or, not ``proven``, a
        draft that already moves at a pinned end (``continuing.draft``), which is never
        returned itself. None when the method does not blend (the move then stops at
        those ends), when nothing is proven, or once the curve and its ends cannot beat
        ``give_up_above`` s together. The default: no blending.
        """
        return None


class KnotTiming(CurveMethod):
    """
    The paper's timing (sections 4.3 and 5).

    The corridor's control points stay where they are; the span durations are optimised
    from the λ-scaled uniform timing (Eq. 12).
    """

    name = 'knot-timing'

    def draft(self, corridor: Corridor, seed: Optional[CubicBSpline] = None) -> Draft:
        """Return the λ-scaled uniform timing of the corridor's control points (no seed)."""
        problem = TimingProblem(corridor.control_points, self.cell.robot, self.settings)
        start = scaled_start(problem)
        return Draft(float(start[0].sum()), (problem, start))

    def finish(self, draft: Draft, give_up_above: Optional[float] = None,
               until: Optional[float] = None,
               deadline: Optional[float] = None) -> Optional[Shaped]:
        """
        Return the spline with optimised span durations (``timing.optimise``).

        The optimisation stops at ``until``, or half-way to ``deadline``, whichever comes
        first, with the fastest timing it has.
        """
        problem, start = draft.work
        stop = min((t for t in (until, _half_way(deadline)) if t is not None), default=None)
        timing = optimise(problem, start, give_up_above, stop)
        if timing is None:
            return None
        warnings = () if timing.optimised else (
            f'time optimisation failed ({timing.message}); returning the λ-scaled timing',)
        metrics = {'lambda': timing.scale, 'optimised': timing.optimised,
                   'solver_iterations': timing.iterations,
                   'constraint_rounds': timing.rounds, 'wafer_samples': timing.samples}
        return Shaped(CubicBSpline.from_intervals(problem.points, timing.intervals),
                      draft.estimate, metrics, warnings)


class WholeCurve(KnotTiming):
    """
    The control points move with the span durations (``shape.optimise_shape``), coarse first.

    The draft is the corridor's λ-scaled start (``KnotTiming``; its cycle time orders the
    elbow-branch combinations). Finishing optimises a curve of
    ``ShapeSettings.coarse_spans`` spans (as many as the path has vertices where that is
    more) fitted to the corridor (``coarse``), then refines
    its optimum to as many spans as the corridor has (``ShapeSettings.min_spans`` at least)
    and optimises that. When the coarse stage proves no curve, it is tried again with as
    many clearance samples as the fine stage will have, then with twice the spans too
    (``coarse_samples``; not within a time budget); when none proves a curve, the fine
    stage starts from the last converged optimum (millimetres into a wall between its
    samples: the fine stage's spans and samples prove it, or a curve near it, in a round
    or two), and, if that proves nothing either, from the corridor curve with optimised
    knot times (``KnotTiming``: feasible by construction), as it does for a curve that
    fails verification: the curve returned is proven collision-free on its own
    (``proof``), not by the corridor. Within a time budget (``until``) the coarse stage
    runs on past it to its first proven curve, up to half-way to the request's
    ``deadline`` (``_past_budget``), and so does a fine stage started from its unproven
    optimum; a fine stage from a proven curve stops at the budget. The metrics
    say where the fine stage started: from the coarse stage's proven curve
    (``coarse_cycle_time`` its cycle time), from its unproven optimum
    (``fine_from_unproven``), or else from the corridor curve.

    Within a time budget, a ``seed`` (a verified optimum between configurations near the
    ends: ``planner.optima``) is tried first: moved to the ends (``warm.moved_to``),
    proven where it lies (not assumed: its ends moved), and optimised at its own spans
    until the budget; the fastest proven curve is the answer (``from_optimum`` in the
    metrics), the moved seed itself where it is proven and nothing beats it. Only when it
    proves none by then, or shows it cannot beat ``give_up_above``, is the corridor's way
    above taken. Without a budget there is no seed: the station table's curves do not
    depend on what was asked before. Within a budget, once another combination has an
    answer (``give_up_above``), nothing runs on past the budget, and a combination whose
    stages prove nothing by then is given up (anytime: the best proven curve by the
    budget is the answer).
    """

    name = 'whole-curve'

    def draft(self, corridor: Corridor, seed: Optional[CubicBSpline] = None) -> Draft:
        """
        Return the corridor's λ-scaled start, keeping the corridor and seed for ``finish``.

        With a seed, its cycle time is the estimate where shorter: near the combination's
        optimum, it is finished first and bounds the others (``give_up_above``).
        """
        start = super().draft(corridor)
        estimate = start.estimate if seed is None else min(start.estimate, seed.duration)
        return Draft(estimate, (start, corridor, seed))

    def finish(self, draft: Draft, give_up_above: Optional[float] = None,
               until: Optional[float] = None,
               deadline: Optional[float] = None) -> Optional[Shaped]:
        """Return the fastest proven curve the whole-curve optimisation found (by ``until``)."""
        start, corridor, seed = draft.work
        if seed is not None and until is not None:
            warm = self._from_seed(seed, corridor, give_up_above, until)
            if warm is not None:
                return replace(warm, fallback=lambda: self._fallback(start))
        # A span per vertex of the path at least: a curve with fewer spans than the path
        # has corners cuts them, into the walls they go round, and is never proven.
        shape, spans = self.shape, max(self.shape.coarse_spans, len(corridor.path))
        fitted_start = coarse_start(corridor.control_points, spans, self.cell.robot,
                                    self.settings)
        # On past the budget to a first proven curve while there is no answer at all; once
        # another combination has one (``give_up_above``), the budget is the end: anytime.
        past = until if give_up_above is not None else _past_budget(until, deadline)
        fine = replace(shape, min_spans=max(shape.min_spans,
                                            len(corridor.control_points) - DEGREE))

        def coarse_stage(keep_out: bool, rounds: int = shape.max_rounds, count: int = spans,
                         samples: int = shape.clearance_samples) -> Optional[Shaping]:
            return optimise_shape(
                fitted_start if count == spans else coarse_start(
                    corridor.control_points, count, self.cell.robot, self.settings),
                self.cell, replace(shape, min_spans=count, max_rounds=rounds,
                                   clearance_samples=samples),
                self.settings,
                None if give_up_above is None else shape.coarse_give_up * give_up_above,
                past, proven=False, first_proven=True, keep_out=keep_out)

        keep_out = _keeps_out(until, deadline)
        coarse = coarse_stage(keep_out)
        if keep_out and breaks_keep_outs(fitted_start, self.cell.motion_model,
                                         shape.port_keep_out):
            # The start passes turned near another port's mouth: pushed out of the disc
            # round it, or under the port rule alone (a second opinion of PLAIN_ROUNDS
            # rounds), whichever proves the faster curve (the first where the optimum
            # grazes the mouth, the second where the way past it is narrow); the fine
            # stage keeps the same.
            plain = coarse_stage(False, min(shape.max_rounds, PLAIN_ROUNDS))
            if _faster(plain, coarse):
                coarse, keep_out = plain, False
        for count in (spans, 2 * spans) if until is None else ():
            # Nothing proven: between its samples an arm link may swing into a wall, and
            # each round chase the last one's collision. Again with as many samples as the
            # fine stage will have (``coarse_samples``), then also with twice the spans;
            # not within a time budget (``coarse_samples``).
            samples = coarse_samples(shape.clearance_samples, count, fine.min_spans)
            if coarse is None or coarse.trajectory is not None or \
                    samples <= shape.clearance_samples:
                break
            again = coarse_stage(keep_out, count=count, samples=samples)
            if _faster(again, coarse):
                coarse = again
        if coarse is None:
            return None  # its optimum is far slower than the best so far
        if coarse.trajectory is not None and coarse.trajectory.duration >= start.estimate:
            coarse = replace(coarse, trajectory=None)  # no faster than the corridor's start
        # The corridor curve is what is returned then: its timing may take longer than the
        # budget (its λ-scaled start can be far slower), up to half-way to the deadline.
        fitted = coarse.trajectory is not None
        shaped = None
        if not fitted and coarse.unproven is not None:
            # Its last optimum lies millimetres into a wall between its samples: the fine
            # stage's spans and samples prove it or a curve near it in a round or two,
            # where from the corridor curve (far slower) its subproblems fail for
            # rounds on end. Within a budget, as the coarse stage, on past it to its
            # first proven curve (half-way to the deadline at most): else the answer is
            # the corridor curve, often twice as slow (seconds of motion, for tenths of
            # a second of planning; doc/benchmark.md).
            shaped = optimise_shape(coarse.unproven, self.cell, fine, self.settings,
                                    give_up_above, past, proven=False,
                                    first_proven=until is not None, keep_out=keep_out)
            if shaped is None:
                return None  # its optimum is far slower than the best so far
            if shaped.trajectory is None:
                shaped = None  # nothing proven: from the corridor curve, then
            else:
                fitted = True
        if not fitted and until is not None and give_up_above is not None:
            return None  # nothing proven by the budget, and another combination has an answer
        timed = None if fitted else super().finish(start, deadline=deadline)
        begin = coarse.trajectory if coarse.trajectory is not None else \
            shaped.trajectory if shaped is not None else timed.trajectory
        if shaped is None:
            shaped = optimise_shape(begin, self.cell, fine, self.settings, give_up_above,
                                    until, keep_out=keep_out)
        if shaped is None:
            return None
        if shaped.trajectory is None:  # nothing proven: the verification refuses it
            shaped = replace(shaped, trajectory=begin)
        warnings = () if shaped.improved or fitted else (
            f'whole-curve optimisation found no faster proven curve ({shaped.message}); '
            'returning the corridor curve',)
        metrics = {'optimised': shaped.improved or fitted,
                   'fine_from_unproven': fitted and coarse.trajectory is None,
                   'coarse_iterations': coarse.iterations,
                   'shape_iterations': shaped.iterations, 'shape_rounds': shaped.rounds,
                   'spans': shaped.spans}
        if coarse.trajectory is not None:
            metrics['coarse_cycle_time'] = coarse.trajectory.duration

        return Shaped(shaped.trajectory, start.estimate, metrics,
                      (timed.warnings if timed else ()) + warnings,
                      lambda: self._fallback(start, timed), optimum=metrics['optimised'])

    def _fallback(self, start: Draft, timed: Optional[Shaped] = None) -> Shaped:
        """Return the corridor curve (``timed``, if already made), said to replace another."""
        corridor_curve = timed or super().finish(start)
        return replace(corridor_curve, warnings=corridor_curve.warnings + (
            "the whole-curve optimisation's curve failed verification; returning the "
            'corridor curve',))

    def _from_seed(self, seed: CubicBSpline, corridor: Corridor,
                   give_up_above: Optional[float], until: float) -> Optional[Shaped]:
        """
        Return the fastest curve proven by ``until`` from ``seed`` moved to the ends, or None.

        None when none is proven by then (``finish`` then starts from the corridor) or the
        optimisation shows it cannot beat ``give_up_above``.
        """
        points, model = corridor.control_points, self.cell.motion_model
        start = moved_to(seed, points[0], points[-1], self.cell.robot, self.settings)
        shape = replace(self.shape, min_spans=max(self.shape.min_spans, len(seed.intervals)))
        # Proven where it lies (a few ms), it is what the optimisation must beat: its
        # first solves, with the default wafer samples, may end a little slower once
        # scaled to the limit between them.
        with stopwatch.timed('optimise.proof'):
            proven = prove(start, model, model.lipschitz).certified
        shaped = optimise_shape(start, self.cell, shape, self.settings, give_up_above, until,
                                proven=proven, keep_out=False)
        if shaped is None or shaped.trajectory is None:
            return None
        return Shaped(shaped.trajectory, start.duration,
                      {'optimised': True, 'from_optimum': True,
                       'shape_iterations': shaped.iterations, 'shape_rounds': shaped.rounds,
                       'spans': shaped.spans}, optimum=True)

    def blend(self, transfer: CubicBSpline, ends, give_up_above: Optional[float] = None,
              until: Optional[float] = None, deadline: Optional[float] = None,
              proven: bool = True) -> Optional[Shaped]:
        """
        Return the whole-curve optimisation of ``transfer`` with its free ends (``blend``).

        The control points and span durations move with each free end's speed, from the
        transfer at rest there (``shape.optimise_shape`` with ``ends``); the fine stage's
        spans. The curve returned is proven; its cycle time is the transfer's alone.
        """
        spans = max(self.shape.min_spans, len(transfer.intervals))
        shaped = optimise_shape(transfer, self.cell, replace(self.shape, min_spans=spans),
                                self.settings, give_up_above,
                                min((t for t in (until, _half_way(deadline)) if t is not None),
                                    default=None), proven=proven, ends=ends,
                                keep_out=_keeps_out(until, deadline))
        if shaped is None or not shaped.improved:
            return None
        return Shaped(shaped.trajectory, transfer.duration,
                      {'optimised': True, 'blend_iterations': shaped.iterations,
                       'blend_rounds': shaped.rounds, 'spans': shaped.spans})


def coarse_samples(per_span: int, spans: int, fine_spans: int) -> int:
    """
    Return clearance samples per span of a coarse stage as dense in time as the fine one.

    ``per_span`` samples on each of the fine stage's ``fine_spans`` spans, spread over the
    coarse stage's ``spans``: the next tries of a coarse stage that proved nothing
    (``WholeCurve.finish``). With ``per_span`` on each of its own spans, a coarse span is
    several fine ones long, and an arm link can swing centimetres into a wall between
    samples: each round added samples where the last curve was refuted, the next went in
    elsewhere, nothing was proven, and the fine stage started from the corridor curve,
    whose optimisation takes seconds more. As the first try they cost more than they
    save: more rows in every subproblem, where a coarse stage usually proves its curve in
    a round or two. Within a time budget they are not made: there the coarse stage already
    runs past the budget to its first proven curve, and the tries would take the answer's
    planning time to seconds (``doc/benchmark.md``: the coarse stage tried again).
    """
    return max(per_span, math.ceil(per_span * fine_spans / spans))


def _keeps_out(until: Optional[float], deadline: Optional[float]) -> bool:
    """
    Return whether the rows keep the discs round other ports' mouths: not within a budget.

    A budgeted answer is the first proven curve, and pushing a start out of a disc costs
    rounds it does not have: within the node's budget, a move past another port's mouth
    came out several per cent slower than unbudgeted with the discs, within rounding of
    it without.
    """
    return until is None and deadline is None


def _past_budget(until: Optional[float], deadline: Optional[float]) -> Optional[float]:
    """
    Return when the coarse stage stops: with a budget (``until``), at its first proven curve.

    Not at the budget's end, but half-way to the request's ``deadline`` at the latest
    (without one, never): until it proves one, there is only the corridor curve, far
    slower than the optimum, while a coarse curve proven late is close to it (the fine
    stage then returns it as it is). None without a budget.
    """
    if until is None:
        return None
    return math.inf if deadline is None else max(until, _half_way(deadline))


def _half_way(deadline: Optional[float]) -> Optional[float]:
    """Return the instant half-way from now to ``deadline`` (None: no deadline)."""
    if deadline is None:
        return None
    now = time.monotonic()
    return now + 0.5 * max(deadline - now, 0.0)


METHODS = {method.name: method for method in (KnotTiming, WholeCurve)}
"""The methods by name."""


def _faster(one: Optional[Shaping], other: Optional[Shaping]) -> bool:
    """Return whether a coarse stage's outcome is better than another's (None: given up)."""
    if one is None or other is None:
        return other is None and one is not None
    if one.trajectory is None or other.trajectory is None:
        return other.trajectory is None and one.trajectory is not None
    return one.trajectory.duration < other.trajectory.duration
