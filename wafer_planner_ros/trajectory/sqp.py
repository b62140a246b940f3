"""
SLSQP's method with a faster subproblem: the whole-curve optimiser's solver.

Problem: minimise c . x (a linear objective) subject to g(x) >= 0 and lb <= x <= ub.
The iteration is Kraft's SLSQP (1988), as scipy runs it: a quasi-Newton matrix B of the
Lagrangian (BFGS with Powell's damping, from the identity or a given B), the quadratic
subproblem ``min c.s + s'Bs/2, g + J s >= 0, lb <= x + s <= ub``, an l1 merit function
with one penalty per constraint (mu = max(u, (mu + u)/2)), a line search that cuts the step
at most ten times (by quadratic interpolation, never below a tenth of the last step), and
the same stopping rule (|f - f_previous| < acc with constraint violation < acc). What
differs:

- the subproblem is solved by daqp (a dual active-set QP solver; dense, for a positive
  definite B) warm-started from the last active set, instead of SLSQP's LSQ/NNLS,
  several times faster on the default cell's problems;
- every step is clipped to the bounds, which daqp meets within its tolerance only;
- an inconsistent linearisation is relaxed by one variable delta in [0, 1] that scales the
  violated rows (SLSQP's device), penalised by ``RELAX_PENALTY``.
"""

from dataclasses import dataclass
from typing import Callable, Optional

import daqp
import numpy as np

from wafer_planner_ros.trajectory.stopwatch import timed

INF = 1e30
"""daqp's infinity."""
RELAX_PENALTY = 100.0
LINE_SEARCH_CUTS = 10
ARMIJO = 0.1
QP_ITERATIONS = 400
"""daqp iterations per subproblem at most: more than the 16-span problems need; the few
larger ones that would need far more, each slow, are relaxed instead, then the solve stops
(doc/benchmark.md)."""


@dataclass(frozen=True, eq=False)
class SqpResult:
    """What ``solve`` returns."""

    x: np.ndarray
    multipliers: np.ndarray
    """Of g >= 0 (>= 0) at the last subproblem."""
    iterations: int
    message: str
    converged: bool
    hessian: np.ndarray
    """B at the end: a start for a solve of a nearby problem in the same variables."""


def solve(evaluate: Callable, c: np.ndarray, x0: np.ndarray, lb: np.ndarray, ub: np.ndarray,
          max_iterations: int = 100, acc: float = 1e-4,
          first: Optional[tuple] = None,
          stop: Optional[Callable[[], bool]] = None,
          qp_iterations: int = QP_ITERATIONS,
          hessian: Optional[np.ndarray] = None) -> SqpResult:
    """
    Minimise c . x subject to evaluate(x)[0] >= 0 and lb <= x <= ub (see the module).

    ``evaluate(x) -> (g (m,), J (m, n))``; ``first``: its value at x0 if known. Bounds may
    be infinite. ``stop()`` true before an iteration ends the solve where it is.
    ``qp_iterations``: daqp iterations per subproblem at most. ``hessian``: B to start from
    (positive definite: a nearby problem's ``SqpResult.hessian``), else the identity.
    """
    n = len(x0)
    lb = np.where(np.isfinite(lb), lb, -INF)
    ub = np.where(np.isfinite(ub), ub, INF)
    x = np.clip(np.asarray(x0, float), lb, ub)
    g, J = evaluate(x) if first is None else first
    m = len(g)
    f = float(c @ x)
    B = np.eye(n) if hessian is None else np.array(hessian, float)
    mu, u = np.zeros(m), np.zeros(m)
    sense = np.zeros(n + m, dtype=np.int32)
    upper_rows = np.full(m, INF)
    message, iteration, reset = 'iteration limit reached', 0, False
    for iteration in range(1, max_iterations + 1):
        if stop is not None and stop():
            message = 'stopped: the time budget ran out'
            break
        lo, hi = lb - x, ub - x
        with timed('optimise.qp'):
            s, _, flag, info = daqp.solve(B, c, J, np.concatenate([hi, upper_rows]),
                                          np.concatenate([lo, -g]), sense,
                                          iter_limit=qp_iterations)
        relaxed = flag < 1
        if relaxed:
            with timed('optimise.qp'):
                s, mult, flag = _relaxed(B, c, J, g, lo, hi, qp_iterations)
            if flag < 1:
                if not reset:  # start B again from the identity once
                    B, reset, sense = np.eye(n), True, np.zeros(n + m, dtype=np.int32)
                    continue
                message = f'subproblem failed (daqp exit flag {flag})'
                break
        else:
            s, mult = np.asarray(s), np.asarray(info['lam'])
            # daqp's sense: 1 active, 2 at the lower bound
            sense = np.where(mult < 0, 3, np.where(mult > 0, 1, 0)).astype(np.int32)
        u = np.maximum(-mult[n:], 0.0)    # daqp: multipliers of lower bounds are negative
        violation = np.maximum(-g, 0.0)
        mu = np.maximum(u, 0.5 * (mu + u))
        merit = f + mu @ violation
        slope = c @ s - mu @ violation
        alpha = 1.0
        for _ in range(LINE_SEARCH_CUTS):
            trial = np.clip(x + alpha * s, lb, ub)
            g_new, J_new = evaluate(trial)
            f_new = float(c @ trial)
            change = f_new + mu @ np.maximum(-g_new, 0.0) - merit
            if change <= ARMIJO * alpha * slope or (slope >= 0.0 and change <= 0.0):
                break
            curvature = 2.0 * (change - alpha * slope)
            alpha = max(-slope * alpha * alpha / curvature if curvature > 0.0 else 0.0,
                        0.1 * alpha)
        B = _bfgs(B, trial - x, (J - J_new).T @ u)    # grad of L = c - J' u
        f_old = f
        x, g, J, f = trial, g_new, J_new, f_new
        if abs(f - f_old) < acc and np.maximum(-g, 0.0).sum() < acc and not relaxed:
            message = 'converged'
            break
    return SqpResult(x, u, iteration, message, message == 'converged', B)


def _relaxed(B, c, J, g, lo, hi, qp_iterations: int) -> tuple:
    """Solve the subproblem with the violated rows scaled by (1 - delta): (s, mult, flag)."""
    n, m = B.shape[0], len(g)
    H = np.zeros((n + 1, n + 1))
    H[:n, :n], H[n, n] = B, RELAX_PENALTY
    A = np.hstack([J, -np.minimum(g, 0.0)[:, None]])
    sx, _, flag, info = daqp.solve(H, np.append(c, 0.0), A,
                                   np.concatenate([hi, [1.0], np.full(m, INF)]),
                                   np.concatenate([lo, [0.0], -g]), iter_limit=qp_iterations)
    if flag < 1:
        return None, None, flag
    mult = np.asarray(info['lam'])
    return np.asarray(sx)[:n], np.concatenate([mult[:n], mult[n + 1:]]), flag


def _bfgs(B: np.ndarray, step: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Return B after the BFGS update with Powell's damping (0.2), as SLSQP does."""
    Bs = B @ step
    sBs = step @ Bs
    if not sBs > 0.0:
        return B
    sy = step @ y
    theta = 1.0 if sy >= 0.2 * sBs else 0.8 * sBs / (sBs - sy)
    r = theta * y + (1.0 - theta) * Bs
    sr = step @ r
    if not sr > 0.0:
        return B
    return B - np.outer(Bs, Bs) / sBs + np.outer(r, r) / sr
