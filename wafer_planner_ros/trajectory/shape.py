"""
Whole-curve optimisation: the control points move together with the span durations.

**Beyond the paper.** The corridor keeps the curve inside tiny boxes at the path's corners,
so the wafer nearly stops there. Here the curve may leave them: its freedom from collision
is proven afterwards on the curve itself (``proof.prove``). Variables: every control point
but the three at each end (the complete stops) and every span duration. Objective: the
total time. Constraints:

- joint velocity, acceleration (and jerk) by their control points: by the convex hull,
  exact everywhere; joint positions by bounds on the control points (the same argument);
- the wafer-centre acceleration on x, y (and |a|) at samples, with the dense check and
  resampling loop of ``timing.optimise``;
- clearance at samples: every body nearer than ``ShapeSettings.watch`` keeps at least
  ``ShapeSettings.clearance`` (less where the start curve itself is closer, so that the
  start stays feasible); the port margins (``geometry.ports``) the same way, as bodies of
  the cell's ``motion_model``, which the proof uses too: they keep a curve that starts
  or ends at a port's mouth from dipping into the port.

The start meets every limit: the corridor curve (also proven: inside its boxes, λ-scaled
to every limit) or a curve fitted to the corridor (``coarse``: not proven, so never
returned), or the optimum of that coarse stage; its knot vector is refined first where it
has few spans. SLSQP's method
solves with exact gradients (``shape_problem``; clearance from the closest points and the
body Jacobian), its quadratic subproblems by daqp (``sqp``), several times faster an iteration
than scipy's SLSQP.
Each answer is scaled by its own λ (Eq. 12) to meet every limit everywhere (and slowed
further where it still exceeds one at the verification's times, ``meet_limits``), then
proven collision-free; where a piece cannot be proven, clearance samples are added there,
and wherever a scan of the curve finds a body nearer a wall than its samples keep, and the
problem is solved again. Only proven curves are kept: the fastest is returned, or
the start (if proven) when none beats it. Each round starts from the last proven curve (or
the start); within a time budget (``deadline``), where each iteration counts, from the last
round's B (the rows it adds change the Lagrangian little) and from its optimum even where
the proof refuted it, up to ``ShapeSettings.warm_rounds`` rounds in a row: a few
iterations each, where from the last proven curve each round took most of the first
one's iterations again.

A curve whose start is pinned to a moving robot's state (``ShapeProblem.pinned``: a divert,
``continuing``) cannot be λ-scaled (slowed, it would leave that state): it is kept only as
solved, where it meets every limit as the verification checks them, and solved again with
the wafer's peaks sampled where it does not.
"""

from dataclasses import dataclass
import logging
import time
from typing import Optional, Sequence

import numpy as np

from wafer_planner_ros.trajectory import sqp
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.proof import prove
from wafer_planner_ros.trajectory.shape_problem import FreeEnd, ShapeProblem
from wafer_planner_ros.trajectory.stopwatch import timed
from wafer_planner_ros.trajectory.timing import peaks_over, single_blas_thread
from wafer_planner_ros.trajectory.timing_problem import TimingProblem
from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings
from wafer_planner_ros.trajectory.verify import limit_ratios

logger = logging.getLogger(__name__)

FAILED_SLOWER = 100.0
"""An answer this many times slower than the start is a failed solve, not a curve."""
PINNED_ROW_NORM = 1e-9
"""A row of a problem with a pinned end (``ShapeProblem.pinned``) whose Jacobian is smaller
than this depends on the pinned motion alone (e.g. the wafer's acceleration at the start):
it is rounding, not a direction, and the row is dropped (it holds as the motion it
continues does)."""
SCAN_STEP = 0.002
"""s: where a curve is not proven, the step at which it is scanned for every stretch nearer
a wall than its samples keep (``_too_near``)."""
SCAN_POINTS = 20000
"""Configurations a scan (``_too_near``) looks at at most: every ``SCAN_STEP`` of a curve of
up to 40 s (the free moves last seconds), more widely spaced on a longer one. A solve that
ends far off (its iteration limit, or a failed subproblem) can leave a curve of many minutes,
under ``FAILED_SLOWER`` times a slow start, which every ``SCAN_STEP`` took seconds to scan,
past the request's deadline: its samples only place the next round's rows."""


@dataclass(frozen=True, eq=False)
class Shaping:
    """The outcome of the whole-curve optimisation."""

    trajectory: Optional[CubicBSpline]
    """The fastest proven curve: the start when nothing beat it, None when the start was not
    proven and nothing was."""
    improved: bool
    iterations: int
    rounds: int
    spans: int
    """Spans after knot refinement."""
    message: str = ''
    unproven: Optional[CubicBSpline] = None
    """When no curve was proven: the curve of the last solve that converged (λ-scaled), which
    the proof refuted, a start for a finer problem; else None."""


def optimise_shape(start: CubicBSpline, cell, shape: ShapeSettings = ShapeSettings(),
                   timing: TimingSettings = TimingSettings(),
                   give_up_above: Optional[float] = None,
                   deadline: Optional[float] = None, proven: bool = True,
                   first_proven: bool = False,
                   ends: Sequence[Optional[FreeEnd]] = (None, None),
                   keep_out: bool = True) -> Optional[Shaping]:
    """
    Return the fastest proven curve from a start that meets every limit (see the module).

    ``give_up_above``: a cycle time (s) this curve need not beat; None is returned as soon
    as a solve's optimum, whose samples are a subset of the final ones, exceeds it by more
    than ``TimingSettings.give_up_margin``. ``deadline``: a ``time.monotonic()`` instant;
    the solver stops there and the fastest proven curve so far is returned (the start at
    worst); with a deadline each solve stops at ``ShapeSettings.budget_ftol``. ``proven``:
    whether the start is proven collision-free (the corridor curve is; a curve fitted to the
    corridor, ``coarse``, is not): if not, it is never returned. ``first_proven``: return
    the first proven curve, not solving again where the wafer limit was exceeded between
    samples (its λ-scaling meets the limit all the same, a little slower). ``ends``: the
    start's and the goal's ``FreeEnd`` (None: at rest there); with free ends every cycle
    time compared is the curve's and its ends' paths' together (``ShapeProblem.total``).
    ``keep_out``: whether the rows keep the discs round the ports' mouths
    (``shape_problem.keep_out_model``; dropped where the first solve fails to push the start
    out of them) or the port rule alone.
    """
    problem = ShapeProblem(start, cell, shape, timing, ends, keep_out)
    current = problem.start
    best = current if proven else None
    spans = problem.spans
    inside = np.arange(shape.wafer_samples) / shape.wafer_samples
    wafer = (np.append(np.repeat(np.arange(spans), len(inside)), spans - 1),
             np.append(np.tile(inside, spans), 1.0))
    around = (np.arange(shape.clearance_samples) + 0.5) / shape.clearance_samples
    grid = (np.repeat(np.arange(spans), len(around)), np.tile(around, spans))
    clearance = _clearance_samples(problem, *grid)
    lower, upper = problem.positions.inner
    iterations, message, unproven = 0, '', None
    proven_last, hessian, warm = current, None, 0
    chained = deadline is not None   # rounds started near the last one's (``warm_rounds``)
    for rounds in range(1, shape.max_rounds + 1):
        if deadline is not None and time.monotonic() >= deadline:
            message = 'the time budget ran out'
            break
        result = _solve(problem, current, wafer, clearance, deadline, hessian)
        hessian = result.hessian if chained else None
        iterations += result.nit
        # The bounds hold to the QP's precision: rounding beyond them is taken back (the
        # fixed end points stay exactly where they are).
        points = result.points.copy()
        points[~problem.fixed] = np.clip(points[~problem.fixed], lower, upper)
        intervals = np.maximum(result.intervals, problem.min_interval)
        points = problem.settled(points, intervals, result.speeds)
        finite = np.all(np.isfinite(points)) and np.all(np.isfinite(intervals))
        if not (finite and intervals.sum() <= FAILED_SLOWER * problem.start.duration) and \
                current is problem.start and problem.drop_keep_outs():
            # The start may break a keep-out round another port's mouth, and the solve
            # that had to push it out failed: solve again with the port rule alone.
            clearance = _clearance_samples(problem, *grid)
            continue
        if not finite:
            message = f'solver failed: {result.message}'
            break
        if intervals.sum() > FAILED_SLOWER * problem.start.duration:
            # A failed solve can end anywhere: once months of motion from a start of
            # seconds, whose dense check alone would not have fit in memory.
            message = (f'solver failed: {result.message} (its answer takes '
                       f'{intervals.sum():.4g} s)')
            break
        if give_up_above is not None and result.converged and \
                problem.total_of(points, intervals) > \
                (1.0 + timing.give_up_margin) * give_up_above:
            logger.debug('shape round %d: T = %.4f s cannot beat %.4f s', rounds,
                         problem.total_of(points, intervals), give_up_above)
            return None
        within = True  # every limit met as the verification checks them (pinned: below)
        with timed('optimise.limits'):
            limits = TimingProblem(points, cell.robot, timing)
            ratio, dense_span, dense_fraction = limits.dense_wafer_ratio(intervals)
            rescale = limits.scale_factor(intervals, ratio.max())
            scaled = rescale * intervals
            reference = problem.start if best is None else best
            if problem.pinned:
                # Slowed, it would no longer move on as its pinned end does: kept only as
                # solved, where that meets every limit as the verification checks them
                # (else solved again, with the wafer's peaks sampled).
                scaled = intervals
                within = all(ratio <= 1.0 for ratio in limit_ratios(
                    CubicBSpline.from_intervals(points, scaled), cell.robot).values())
            elif problem.total_of(points, scaled) >= problem.total(reference):
                # Scaled, it cannot be kept: not checked every millisecond as a curve that
                # may be kept is, which costs time in proportion to its length (an answer
                # stopped mid-solve, far over the limits, can scale to an hour's motion).
                if deadline is not None and time.monotonic() >= deadline:
                    message = 'the time budget ran out'
                    break
            else:
                scaled = limits.meet_limits(scaled)[0]
            curve = CubicBSpline.from_intervals(points, scaled)
        with timed('optimise.proof'):
            proof = prove(curve, problem.model, problem.model.lipschitz)
        logger.debug('shape round %d: %s, %d iterations, T = %.4f s (x %.4f; wafer %.3f), '
                     'proven %s, min span %.4f s', rounds, result.message, result.nit,
                     curve.duration, rescale, ratio.max(), proof.certified, intervals.min())
        if not (proof.certified or proven or result.converged
                or result.nit >= shape.max_iterations):
            # From a start not proven the solver failed (not even its iteration limit) and
            # nothing is proven: more samples would only make its problem harder.
            message = f'no curve was proven ({result.message})'
            break
        if proof.certified:
            current = proven_last = curve  # feasible everywhere: the next solve starts there
            warm = 0
            # Kept only if faster than the best so far, or than the start when it is not
            # proven (a failed solve can end on a far slower curve that is still proven).
            if within and problem.total(curve) < problem.total(
                    problem.start if best is None else best):
                best = curve
            if first_proven or (within and rescale <= 1.0 + timing.rescale_tolerance):
                break
        else:
            if result.converged:
                unproven = curve
            if chained and result.converged and warm < shape.warm_rounds:
                current, warm = curve, warm + 1   # near the next optimum (``warm_rounds``)
            else:
                current, hessian, warm = proven_last, None, 0
            # Sample the pieces that could not be proven, for every body, and every stretch
            # of the curve nearer a wall than the samples keep (the proof stops at its
            # first collision: one sample a round would leave the others for later rounds),
            # and solve again.
            times = np.concatenate([proof.unproven.mean(axis=1), proof.unproven.ravel()])
            if proof.collision is not None:
                times = np.append(times, proof.collision)
            times = np.append(times, _too_near(problem, curve))
            more = _clearance_samples(problem, *_at_times(curve, times), every_body=True,
                                      curve=curve)
            clearance = tuple(np.concatenate([a, b]) for a, b in zip(clearance, more))
        if rescale > 1.0 + timing.rescale_tolerance or not within:
            # Between samples the wafer limit was exceeded: sample the peaks.
            peaks = peaks_over(ratio, timing.margin * (1.0 + 2e-4))
            wafer = (np.append(wafer[0], dense_span[peaks]),
                     np.append(wafer[1], dense_fraction[peaks]))
    improved = best is not None and best is not problem.start
    if not improved and not message:
        message = 'no proven curve beat the start' if proven else 'no curve was proven'
    return Shaping(best, improved, iterations, rounds, spans, message,
                   unproven if best is None else None)


def _too_near(problem: ShapeProblem, curve: CubicBSpline) -> np.ndarray:
    """
    Return the times at which a body or a port margin of ``curve`` is nearer than kept.

    The curve is scanned every ``SCAN_STEP`` (at ``SCAN_POINTS`` at most); of each stretch
    where a column of the clearance (``_kept``) falls short, its first, nearest and last
    times.
    """
    times = np.linspace(0.0, curve.duration, min(
        max(2, int(np.ceil(curve.duration / SCAN_STEP)) + 1), SCAN_POINTS))
    clearance = problem.model.body_clearance(curve.evaluate(times))
    short = clearance < _kept(problem)
    found = []
    for column in np.nonzero(short.any(axis=0))[0]:
        edges = np.flatnonzero(np.diff(np.concatenate([[0], short[:, column], [0]])))
        for first, end in zip(edges[::2], edges[1::2]):
            nearest = first + int(np.argmin(clearance[first:end, column]))
            found += [times[first], times[nearest], times[end - 1]]
    return np.asarray(found, float)


def _kept(problem: ShapeProblem) -> np.ndarray:
    """Return what the samples keep of each column (every body, every port margin) (m)."""
    model = problem.model
    return np.concatenate([np.full(model.bodies, problem.settings.clearance),
                           problem.settings.port_kept * model.tolerances])


def _clearance_samples(problem: ShapeProblem, span, fraction, every_body: bool = False,
                       curve: Optional[CubicBSpline] = None) -> tuple:
    """
    Return (span, fraction, body, kept) rows for the bodies near the walls at samples.

    Near: within ``ShapeSettings.watch`` on the start curve or on ``curve``; with
    ``every_body`` every body of the robot, and the port margins that are near.

    ``kept``: the clearance a body keeps there, ``ShapeSettings.clearance`` or, where the
    start curve is closer, half of the start's (where an unproven start touches a wall,
    ``ShapeSettings.clearance``); for a port margin ``ShapeSettings.port_kept`` of the
    port's lateral tolerance in place of ``ShapeSettings.clearance`` (a margin is at most
    the tolerance).
    """
    span, fraction = np.asarray(span, np.int64), np.asarray(fraction, float)
    start = problem.clearances(problem.start, span, fraction)          # (K, 4 + 4P)
    model = problem.model
    near = start < problem.settings.watch
    if every_body:
        near[:, :model.bodies] = True
    if curve is not None:
        on_curve = problem.clearances(curve, span, fraction)
        near |= on_curve < problem.settings.watch
    k, body = np.nonzero(near)
    wanted = _kept(problem)[body]
    start = start[k, body]
    kept = np.where(start > 0.0, np.minimum(wanted, 0.5 * start), wanted)
    return span[k], fraction[k], body, kept


def _at_times(curve: CubicBSpline, times) -> tuple:
    """Return (span, fraction) of times on a curve."""
    breaks = curve.breaks()
    times = np.clip(np.asarray(times, float), 0.0, curve.duration)
    span = np.clip(np.searchsorted(breaks, times, side='right') - 1, 0, len(breaks) - 2)
    fraction = np.clip((times - breaks[span]) / np.diff(breaks)[span], 0.0, 1.0)
    return span, fraction


@dataclass(frozen=True, eq=False)
class _Solved:
    """What one SLSQP run returned."""

    points: np.ndarray
    intervals: np.ndarray
    nit: int
    message: str
    converged: bool
    """The solver stopped at an optimum (not at its iteration limit or a failure)."""
    speeds: tuple = ()
    """Each free end's (v, a) (``shape_problem.FreeEnd``)."""
    hessian: Optional[tuple] = None
    """(the solver's last B, the durations' scale of its variables): the next round's B."""


def _solve(problem: ShapeProblem, start: CubicBSpline, wafer, clearance,
           deadline: Optional[float] = None, hessian: Optional[tuple] = None):
    """
    Run SLSQP's method (``sqp``) from ``start``: durations relative to the start's.

    The free control points are bounded by the position limits, ``PositionBound.margin``
    inside (the QP's simple bounds: bounding only those near a limit, and the rest when
    they crossed one, was slower, solving some rounds twice); at ``deadline``
    (``time.monotonic()``) it stops where it is. Rows are weighted to norm 1 near the
    start, rows that do not depend on the variables dropped: unweighted, with Jacobian
    entries many orders of magnitude apart, SLSQP's subproblem took several times as long
    per iteration. ``hessian``: a round's ``_Solved.hessian``, B to start from (its duration
    columns rescaled to this start's), else the identity.
    """
    single_blas_thread()
    scale = start.intervals.copy()
    first_b = None
    if hessian is not None:
        first_b, before = hessian
        rescaled = np.ones(len(first_b))  # d (x then) / d x, for the durations' columns
        rescaled[problem.duration_columns] = scale / before
        first_b = first_b * np.outer(rescaled, rescaled)
    x0 = problem.pack(start.control_points, start.intervals, scale)
    # A row's norm at the start and at a point nearby: zero at both, it does not depend on
    # the variables at all (a velocity control point between two fixed points); zero at
    # the start alone, it is a squared limit at zero speed there and stays in.
    nearby = x0 + np.random.default_rng(0).uniform(-1e-3, 1e-3, len(x0))
    norms = []
    for x in (x0, nearby):
        with timed('optimise.rows'):
            values, jacobian = problem.rows(x, wafer, clearance, scale)
        norms.append(np.linalg.norm(jacobian, axis=1))
        if x is x0:
            first = (values, jacobian)
    norms = np.maximum(*norms)
    keep = norms > (PINNED_ROW_NORM if problem.pinned else 1e-12)
    weights = 1.0 / norms[keep]

    def linearised(x):
        with timed('optimise.rows'):
            values, jacobian = problem.rows(x, wafer, clearance, scale)
            return values[keep] * weights, jacobian[keep] * weights[:, None]

    lb, ub = problem.bounds(*problem.positions.inner, scale)
    objective = problem.objective(scale)
    result = sqp.solve(linearised, objective, x0, lb, ub,
                       max_iterations=problem.settings.max_iterations,
                       acc=problem.settings.ftol if deadline is None else
                       problem.settings.budget_ftol,
                       first=(first[0][keep] * weights, first[1][keep] * weights[:, None]),
                       stop=None if deadline is None else
                       (lambda: time.monotonic() >= deadline),
                       qp_iterations=problem.settings.qp_iterations, hessian=first_b)
    points, intervals = problem.unpack(result.x, scale)
    return _Solved(points, intervals, result.iterations, result.message, result.converged,
                   tuple(problem.speeds_of(result.x)), (result.hessian, scale))
