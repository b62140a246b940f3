"""
Time optimisation of the knot intervals (paper sections 4.3 and 5).

The optimiser of ``timing_problem.TimingProblem``, tuned by ``tuning.TimingSettings``.
Variables: the durations h of the spline's spans. Objective: the total time sum(h)
(Eq. 11). Constraints, all as ``1 - (x / (margin * limit))**2 >= 0``:

- joint velocity and acceleration control points (Eq. 6-8), and jerk control points when
  the cell sets a jerk limit; by the convex-hull property these bound the curve everywhere.
  Those below 70 % of their limit are left out of the solver (an active set) and added
  back when a solution brings them closer (``TimingSettings.active``);
- the wafer-centre acceleration on x and y (Eq. 9), and on |a| when the cell sets
  ``wafer_acceleration_norm_limit``, at constraint samples: the paper's, at every knot;
- ``h >= min_interval``: Eq. 10 as printed would force every span to last the whole
  straight-line time, so it is read as a positive lower bound: 1 ms when the cell limits
  jerk (the jerk control points then keep spans apart), 20 ms when it does not
  (``TimingSettings.shortest``).

The start point is the paper's λ-scaled uniform timing (Eq. 12), with λ computed from a
dense sample of the wafer acceleration, and slowed further where it still exceeds a limit
at the verification's own times (``TimingProblem.meet_limits``), so that it is feasible
everywhere; SLSQP's method then solves with exact gradients (compiled, ``rows``), as
``sqp`` runs it (daqp for the subproblems: the same cycle times as scipy's SLSQP, in less
time; doc/benchmark.md). The control-point
rows are Eq. 6-7 differentiated in closed form; a wafer sample in span s depends on
h_{s-2}..h_{s+2} only, and its derivatives come by the complex step on the spline's basis
(every function is analytic, so ``Im B(h + i ε e_k) / ε`` is dB/dh_k to machine precision
— there is no difference to cancel, unlike finite differences) through the kinematics'
closed-form partials.

**Beyond the paper**: sampling the wafer acceleration at the knots lets it exceed the limit
between them. Every answer of the solver is therefore checked densely (every ``dense_step``
seconds, and every control point) and scaled by its own λ of Eq. 12, which makes it
feasible everywhere (one that would be the fastest so far is checked as the start is,
``meet_limits``); if that scaling slows it by more than ``rescale_tolerance``, the local
peaks over the limit become new samples and the problem is solved again (at most
``max_rounds`` times). The fastest feasible answer is kept; only when the solver produced
nothing usable is the λ-scaled start returned, with the reason. At a deadline the solver
stops where it is, and that answer, scaled the same way, is kept if it is the fastest: any
timing scaled by its own λ meets every limit, so the optimisation can stop at any
iteration. Mid-solve answers, which break limits, often scale back to the start's cycle
time or slower, the earlier they are stopped: a converged round is what pays.

Limits are tightened by ``margin`` inside the optimiser so that what lies between dense
samples stays below the true limits that verification applies.
"""

from dataclasses import dataclass
import functools
import logging
import time
from typing import Optional

import numpy as np
from threadpoolctl import threadpool_limits

from wafer_planner_ros.trajectory import sqp
from wafer_planner_ros.trajectory.timing_problem import Samples, scaled_start, Timing
from wafer_planner_ros.trajectory.timing_problem import TimingProblem

logger = logging.getLogger(__name__)


def optimise(problem: TimingProblem, start=None, give_up_above=None,
             deadline: Optional[float] = None, quiet: bool = False) -> Optional[Timing]:
    """
    Return the optimised timing of the problem (see the module's description).

    ``start``: ``scaled_start(problem)`` if the caller already has it. ``give_up_above``:
    a cycle time (s) this problem need not beat; None is returned as soon as a round's
    optimum, whose samples are a subset of the final ones, exceeds it by more than
    ``give_up_margin`` (the planner uses it to drop an elbow-branch combination that
    cannot win). ``deadline``: a ``time.monotonic()`` instant at which the solver stops and
    the fastest feasible timing so far is returned. ``quiet``: returning the start is no
    news (a start already close to the optimum), logged at debug level, not as a warning.
    """
    tuning = problem.settings
    start, scale = start or scaled_start(problem)
    # The paper's samples, every knot, plus tuning.samples_per_span - 1 more inside each span.
    inside = np.arange(tuning.samples_per_span) / tuning.samples_per_span
    span = np.append(np.repeat(np.arange(problem.spans), len(inside)), problem.spans - 1)
    fraction = np.append(np.tile(inside, problem.spans), 1.0)
    # Control-point constraints far from their limit are left out until they come close.
    rows = problem.control_constraints(start) <= tuning.active
    best, intervals, iterations = start, start, 0
    for rounds in range(1, tuning.max_rounds + 1):
        result = _solve(problem, intervals, problem.samples(span, fraction), rows, deadline)
        logger.debug('round %d: %s (%d iterations, T = %.4f s)', rounds, result.message,
                     result.iterations, result.intervals.sum())
        iterations += result.iterations
        if not np.all(np.isfinite(result.intervals)):
            break
        intervals = np.maximum(result.intervals, problem.min_interval)
        if give_up_above is not None and result.converged and \
                intervals.sum() > (1.0 + tuning.give_up_margin) * give_up_above:
            logger.debug('round %d: T = %.4f s cannot beat %.4f s', rounds, intervals.sum(),
                         give_up_above)
            return None
        # Eq. 12 applied to the solver's answer makes it feasible everywhere (dense check).
        ratio, dense_span, dense_fraction = problem.dense_wafer_ratio(intervals)
        rescale = problem.scale_factor(intervals, ratio.max())
        if rescale * intervals.sum() < best.sum():
            scaled = problem.meet_limits(rescale * intervals)[0]
            best = scaled if scaled.sum() < best.sum() else best
        if rescale <= 1.0 + tuning.rescale_tolerance:
            return Timing(best, start, scale, True, iterations, rounds, len(span))
        if deadline is not None and time.monotonic() >= deadline:
            break
        # Between samples the limit was exceeded: sample the peaks and solve again.
        rows |= problem.control_constraints(intervals) <= tuning.active
        peaks = peaks_over(ratio, tuning.margin * (1.0 + 2e-4))
        span = np.append(span, dense_span[peaks])
        fraction = np.append(fraction, dense_fraction[peaks])
    if best is start:
        message = f'solver failed: {result.message}' if not result.converged else \
            'no answer of the solver, scaled to meet every limit, beat the start'
        logger.log(logging.DEBUG if quiet else logging.WARNING,
                   'time optimisation fell back to the λ-scaled timing: %s', message)
        return Timing(start, start, scale, False, iterations, rounds, len(span), message)
    return Timing(best, start, scale, True, iterations, rounds, len(span),
                  f'stopped after {rounds} rounds, rescaled by {rescale:.4f}')


def peaks_over(ratio: np.ndarray, threshold: float) -> np.ndarray:
    """Return the indices of the local maxima of ``ratio`` that exceed ``threshold``."""
    padded = np.concatenate([[-np.inf], ratio, [-np.inf]])
    peak = (ratio >= padded[:-2]) & (ratio > padded[2:]) & (ratio > threshold)
    return np.nonzero(peak)[0]


@functools.cache
def single_blas_thread():
    """
    Have BLAS (OpenBLAS under numpy and scipy) use one thread in this process, once.

    The optimisers' problems are small (tens of variables, hundreds of rows): the two
    threads OpenBLAS starts by default made each solve several times slower on the 2-core
    machine, and the threads it spins also slow every other thread of the node.
    """
    return threadpool_limits(limits=1, user_api='blas')


def _solve(problem: TimingProblem, start: np.ndarray, samples: Samples, rows,
           deadline: Optional[float] = None) -> '_Solved':
    """
    Run SLSQP's method (``sqp``) from ``start``, until ``deadline`` at most.

    The variables are the durations relative to ``start`` (all 1 at the start), which suits
    the initial identity Hessian: fewer iterations and slightly shorter cycle times than
    with the durations themselves.
    The result's ``intervals`` are the durations (s).
    """
    single_blas_thread()
    scale = start.copy()

    def linearised(x):
        values, jacobian = problem.linearise(x * scale, samples, rows)
        return values, jacobian * scale

    result = sqp.solve(linearised, scale, np.ones_like(scale), problem.min_interval / scale,
                       np.full(len(scale), np.inf),
                       max_iterations=problem.settings.max_iterations,
                       acc=problem.settings.ftol,
                       stop=None if deadline is None else
                       (lambda: time.monotonic() >= deadline))
    return _Solved(result.x * scale, result.iterations, result.message, result.converged)


@dataclass(frozen=True, eq=False)
class _Solved:
    """What one solve returned."""

    intervals: np.ndarray
    iterations: int
    message: str
    converged: bool
