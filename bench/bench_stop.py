"""
Controlled stops against the time-optimal stop on the same path without a jerk limit.

On the default cell (roadmap seed 0, ``load_or_build``), planned by the whole-curve
optimiser unbudgeted against the loaded limit set: every station pair (``station_pairs``)
and every ``<loadport>:inside`` -> ``<loadlock>:inside`` move through the ports and back.
At 20 moments of each move, evenly spaced strictly inside (0, T) (k T / 21, k = 1..20):

- ours: ``Planner.stop(move, at)``, verified as every answer is (given the move's
  verification, as the node holds it for what it published): its duration, its wafer
  travel (the length of the wafer centre's path during the stop, sampled every 0.5 ms),
  'braked' or 'rest' (no braked timing kept the limits: the rest of the move is the stop),
  its planning ms (stop, verify, total);
- the reference: the time-optimal stop on the same path without a jerk limit in TOPP-RA's
  constraint model. The path is the move from ``at`` on (``TailPath``: its parameter is
  the move's own time, so the path speed there is exactly 1), the constraints those of
  ``bench_plan.toppra_time`` (joint velocity, joint acceleration, the wafer acceleration on
  x and y as a ``SecondOrderConstraint``), collocated on a grid 0.5 ms of path time apart:
  ``compute_constraint_params`` gives at each gridpoint linear rows in (u, x) = (s'', s'^2).
  The stop brakes as hard as those rows allow at every stage (``greedy``): x0 = 1, u the
  least feasible (a stage where no u < 0 is feasible keeps u = 0: the path is followed as
  it is), x_{i+1} = x_i + 2 u ds, until x reaches 0 within a stage; its time is the sum of
  2 ds / (sqrt(x_i) + sqrt(x_{i+1})). This is the lowest path speed any timing within those
  rows can have at every point of the path (no jerk limit: the deceleration may jump), so
  no stop on this path comes to rest at an earlier point. Being slowest everywhere is not
  quite being soonest at rest, though: where more deceleration is available a little
  further on, following the move a while and then braking can be sooner. So the reference
  reported is the best of those (``best_stop``: follow the move to each gridpoint, then
  brake as hard as the rows allow; the rest of the move included), which is never later
  than the rest of the move and at most the pure braking one (reported too:
  ``greedy_duration``). Stops that speed up first are not searched here; TOPP-RA's own
  solver, which may (``TOPPRA.compute_parameterization(1, 0)`` on the path cut at end
  points 0.5 ms apart near this stop's), found no sooner stop on 5 moments of two station
  moves: its soonest came 0.1-0.6 ms later (its end on a gridpoint).
  Under the jerk limit no stop can brake that hard at once, so the reference is what any
  jerk-limited stop on this path is measured against (a lower bound up to that caveat).
- the jerk floor: each joint's time-optimal jerk-limited stop from its state at ``at``
  alone (``joint_floor``: no path, no wafer), the largest of the three; no stop under the
  jerk limits is sooner. Ours over the larger of it and the reference says how much of
  the gap the jerk limit alone explains (a move accelerating hard must first reverse it);
- the abrupt hold a controller makes on its own: ``hold_demand(move, at, robot)`` over the
  wafer limit (the ratio; above 1 the wafer would slide).

The reference is checked first on a path with constant bounds (a straight line in joint
space under joint limits alone: the stop must take v / a) and every row on it never being
later than the rest of the move. Reported per move and overall: ours / the reference
(median, p90, max, over every moment and over the 'braked' ones alone), the share of
'rest', the wafer travel of both, the hold demand ratio (median, max), planning ms
(median, p99, max). Target (the issue): ours <= 1.15 x the reference, median. Writes
``bench/results/stop.json`` (every row, the summary, the machine and commit); prints a
table.

Run: ``python bench/bench_stop.py [--moments 20] [--moves N]`` (``--moves`` keeps the first
N moves, for a quick run).
"""

import argparse
import json
import os
from pathlib import Path
import platform
import subprocess
import sys
import time

from bench_plan import CurvePath  # bench/: this script's folder is on the path
import numba
import numpy as np
import toppra.constraint as tc

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.service.cycle import loadport_loadlock_pairs
from wafer_planner_ros.trajectory.methods import WholeCurve
from wafer_planner_ros.trajectory.stopping import hold_demand

HERE = Path(__file__).resolve().parent
RESULTS = HERE / 'results' / 'stop.json'
GRID = 0.0005
"""s of the move's own time between the reference's gridpoints (and the travel samples)."""
TARGET = 1.15
"""Ours / the reference, median: the issue's target."""
COLLOCATION = tc.DiscretizationType.Collocation


class TailPath(CurvePath):
    """The move from ``begin`` to its end as TOPP-RA's path; the parameter is its own time."""

    def __init__(self, trajectory, begin: float):
        """Wrap a planner trajectory from ``begin`` (s of its own time) on."""
        super().__init__(trajectory)
        self.begin = begin

    @property
    def path_interval(self):
        """Return the parameter range [begin, duration]."""
        return np.array([self.begin, self.trajectory.duration])


def constraints(robot) -> list:
    """Return ``bench_plan.toppra_time``'s constraints, each collocated at the gridpoints."""
    arm, limit = robot.arm, robot.wafer_limit.xy
    velocity = tc.JointVelocityConstraint(np.column_stack([-robot.limits.velocity,
                                                           robot.limits.velocity]))
    acceleration = tc.JointAccelerationConstraint(
        np.column_stack([-robot.limits.acceleration, robot.limits.acceleration]),
        discretization_scheme=COLLOCATION)
    wafer = tc.SecondOrderConstraint(
        lambda q, qd, qdd: arm.wafer_acceleration(q, qd, qdd),
        lambda q: np.vstack([np.eye(2), -np.eye(2)]),
        lambda q: np.concatenate([limit, limit]), dof=3,
        discretization_scheme=COLLOCATION)
    return [velocity, acceleration, wafer]


def stage_rows(path, gridpoints, robot) -> tuple:
    """
    Return the constraints' rows at the gridpoints: (U, X, R, xmax).

    Row k of gridpoint i: U[i, k] u + X[i, k] x <= R[i, k] (from TOPP-RA's a u + b x + c = v,
    F v <= g); xmax[i]: the largest x the velocity limits leave.
    """
    count = len(gridpoints)
    us, xs, rs = [], [], []
    xmax = np.full(count, np.inf)
    for constraint in constraints(robot):
        a, b, c, f, g, ubound, xbound = constraint.compute_constraint_params(path, gridpoints)
        if xbound is not None:
            xmax = np.minimum(xmax, xbound[:, 1])
        if a is None:
            continue
        if constraint.identical:
            us.append(a @ f.T)
            xs.append(b @ f.T)
            rs.append(g[None, :] - c @ f.T)
        else:
            us.append(np.einsum('ikm,im->ik', f, a))
            xs.append(np.einsum('ikm,im->ik', f, b))
            rs.append(g - np.einsum('ikm,im->ik', f, c))
    return (np.ascontiguousarray(np.hstack(us)), np.ascontiguousarray(np.hstack(xs)),
            np.ascontiguousarray(np.hstack(rs)), xmax)


@numba.njit(cache=True)
def greedy(s, U, X, R, start, x0):
    """
    Return (time, path time at rest, forced stages) of braking hardest from gridpoint start.

    From x = x0 at ``s[start]``: at each stage the least u the rows allow at x (u = 0 where
    none below 0 is: a 'forced' stage), x_{i+1} = x_i + 2 u ds, until x reaches 0 within
    a stage (its time sqrt(x) / -u). A stage whose rows do not bound u below (the path's
    derivative zero: at the move's end) stops at once. Past the last gridpoint the move
    is at rest (its end).
    """
    x = x0
    t = 0.0
    forced = 0
    for i in range(start, len(s) - 1):
        ds = s[i + 1] - s[i]
        low = -np.inf
        for k in range(U.shape[1]):
            a = U[i, k]
            if a < -1e-12:
                low = max(low, (R[i, k] - X[i, k] * x) / a)
        if low == -np.inf:
            return t, s[i], forced
        if low >= 0.0:
            forced += 1
            low = 0.0
        if low < 0.0 and x + 2.0 * low * ds <= 0.0:
            return t + np.sqrt(x) / -low, s[i] + x / (-2.0 * low), forced
        after = x + 2.0 * low * ds
        t += 2.0 * ds / (np.sqrt(x) + np.sqrt(after))
        x = after
    return t, s[len(s) - 1], forced


@numba.njit(cache=True)
def best_stop(s, U, X, R):
    """
    Return (time, path time at rest, path time braking begins) of the soonest stop.

    Of the stops that follow the move (x = 1) to a gridpoint and then brake hardest from
    there (``greedy``), the rest of the move included (braking at its end).
    """
    best, rest, _ = greedy(s, U, X, R, 0, 1.0)
    switch = s[0]
    for k in range(1, len(s)):
        follow = s[k] - s[0]
        if follow >= best:
            break
        t, at_rest, _ = greedy(s, U, X, R, k, 1.0)
        if follow + t < best:
            best, rest, switch = follow + t, at_rest, s[k]
    return best, rest, switch


def reference(move, at: float, robot, rows=None) -> dict:
    """
    Return the reference stop of ``move`` from ``at`` (the module): durations and travel.

    ``rows``: (gridpoints, U, X, R) over the whole move, to slice from ``at`` (a gridpoint);
    made here if None.
    """
    if rows is None:
        grid = path_grid(move.duration, [at])
        rows = (grid,) + stage_rows(TailPath(move, 0.0), grid, robot)[:3]
    grid, U, X, R = rows
    first = int(np.searchsorted(grid, at))
    assert abs(grid[first] - at) < 1e-12, 'at must be a gridpoint'
    s, U, X, R = grid[first:], U[first:], X[first:], R[first:]
    started = time.perf_counter()
    greedy_time, greedy_rest, forced = greedy(s, U, X, R, 0, 1.0)
    best_time, best_rest, switch = best_stop(s, U, X, R)
    seconds = time.perf_counter() - started
    return {'duration': float(best_time), 'rest_at': float(best_rest),
            'follows': float(switch - at),
            'travel': wafer_travel(move, np.append(s[s < best_rest], best_rest), robot),
            'greedy_duration': float(greedy_time), 'greedy_rest_at': float(greedy_rest),
            'greedy_travel': wafer_travel(move, np.append(s[s < greedy_rest], greedy_rest),
                                          robot),
            'forced_stages': int(forced), 'ms': 1e3 * seconds}


def path_grid(duration: float, moments) -> np.ndarray:
    """Return gridpoints GRID apart over [0, duration] with the moments among them."""
    grid = np.linspace(0.0, duration, int(np.ceil(duration / GRID)) + 1)
    return np.unique(np.concatenate([grid, np.asarray(moments, float)]))


def wafer_travel(trajectory, t, robot) -> float:
    """Return the length (m) of the wafer centre's path through ``trajectory`` at times t."""
    centre = robot.arm.wafer_center(trajectory.evaluate(np.asarray(t, float)))
    return float(np.linalg.norm(np.diff(centre, axis=0), axis=1).sum())


class Line:
    """A straight line in joint space at constant speed: q(s) = q0 + d s, s in [0, T]."""

    def __init__(self, q0, d, duration):
        """Keep the start, the velocity and the duration."""
        self.q0, self.d, self.duration = np.asarray(q0, float), np.asarray(d, float), duration

    def evaluate(self, s, order=0):
        """Return q or its derivative of ``order`` at s, (len(s), 3)."""
        s = np.atleast_1d(np.asarray(s, float))[:, None]
        if order == 0:
            return self.q0 + self.d * s
        return np.broadcast_to(self.d if order == 1 else 0.0 * self.d, (len(s), 3)).copy()


def check_constant_bounds(robot) -> dict:
    """
    Check the reference where it is known: a line under constant joint limits takes v / a.

    On a straight joint-space line at speed d (the path speed 1), the joint acceleration
    rows alone bound u >= -a with a = min_j A_j / |d_j|: the stop takes 1 / a; the wafer
    rows are left out (not constant on a line). Returns both and their difference.
    """
    line = Line([0.3, -0.4, 0.2], [1.0, -1.5, 0.7], 2.0)
    grid = path_grid(line.duration, [0.25])
    rows = stage_rows(TailPath(line, 0.0), grid, robot)
    keep = slice(0, 6)  # the joint acceleration rows (the wafer's four follow)
    first = int(np.searchsorted(grid, 0.25))
    U, X, R = (np.ascontiguousarray(m[first:, keep]) for m in rows[:3])
    duration = greedy(grid[first:], U, X, R, 0, 1.0)[0]
    best = best_stop(grid[first:], U, X, R)[0]
    expected = 1.0 / np.min(robot.limits.acceleration / np.abs(line.d))
    return {'line_stop_s': float(duration), 'best_s': float(best), 'v_over_a_s': float(expected),
            'difference_s': float(duration - expected)}


def joint_floor(v0: float, a0: float, acceleration: float, jerk: float) -> float:
    """
    Return the least time (s) one joint takes from (v0, a0) to rest under |a| <= A, |j| <= J.

    The time-optimal jerk-limited stop of one axis alone (jerk to a peak deceleration, held
    at A if it gets there, then back to zero): whatever the path, no stop of the arm
    rests this joint sooner.
    """
    after = v0 + a0 * abs(a0) / (2.0 * jerk)  # the velocity once the acceleration is gone
    if after == 0.0:
        return abs(a0) / jerk
    if after < 0.0:
        v0, a0 = -v0, -a0  # the mirror image: now the joint must decelerate
    peak = np.sqrt(max(0.5 * a0 * a0 + jerk * v0, 0.0))
    if peak <= acceleration:
        return (a0 + 2.0 * peak) / jerk
    cruise = (v0 + (a0 * a0 - 2.0 * acceleration ** 2) / (2.0 * jerk)) / acceleration
    return (a0 + 2.0 * acceleration) / jerk + cruise


def jerk_floor(move, at: float, robot) -> float:
    """Return the largest ``joint_floor`` of the joints in the move's state at ``at``."""
    _, v, a = (x[0] for x in move.evaluate_orders([float(at)], (0, 1, 2)))
    limits = robot.limit_set.joints
    return max(joint_floor(v[j], a[j], limits.acceleration[j], limits.jerk[j])
               for j in range(3))


def moves_of(cell) -> list:
    """Return the moves: every station pair, then through the ports both ways (by name)."""
    moves = [('station', a, b) for a, b in station_pairs(cell)]
    for loadport, loadlock in loadport_loadlock_pairs(cell):
        moves.append(('port', f'{loadport}:inside', f'{loadlock}:inside'))
        moves.append(('port', f'{loadlock}:inside', f'{loadport}:inside'))
    return moves


def stop_row(planner, move, at: float, rows, label: str, verified=None) -> dict:
    """
    Return one moment's figures: our stop, the reference, the hold.

    ``verified``: the move's verification, as the node holds it for the moves it answered.
    """
    robot = planner.cell.robot
    row = {'at': at, 'rest_of_move': move.duration - at}
    try:
        result = planner.stop(move, at, label, verified=verified)
    except PlanningError as exc:
        row.update(error=f'{exc.code.name}: {exc.message}')
        return row
    stop = result.trajectory
    t = np.append(np.arange(0.0, stop.duration, GRID), stop.duration)
    ref = reference(move, at, robot, rows)
    demand = hold_demand(move, at, robot)
    floor = jerk_floor(move, at, robot)
    row.update(error=None, duration=stop.duration, travel=wafer_travel(stop, t, robot),
               timing=result.metrics['timing'], share=result.metrics['share'],
               ms=dict(result.timings_ms), reference=ref,
               ratio=stop.duration / ref['duration'],
               greedy_ratio=stop.duration / ref['greedy_duration'], jerk_floor=floor,
               floor_ratio=stop.duration / max(ref['duration'], floor),
               hold_demand=demand, hold_ratio=demand / float(np.min(robot.wafer_limit.xy)))
    return row


def _stats(values, high: str = 'p90') -> dict:
    """Return the median, a high percentile (p90 or p99) and the max of the values."""
    values = np.asarray([v for v in values if v is not None], float)
    if not len(values):
        return {}
    return {'median': float(np.median(values)),
            high: float(np.percentile(values, int(high[1:]))),
            'max': float(values.max()), 'n': int(len(values))}


def summary_of(rows) -> dict:
    """Return the summary of some rows (one move's or all)."""
    ok = [r for r in rows if r.get('error') is None]
    braked = [r for r in ok if r['timing'] == 'braked']
    return {
        'moments': len(rows), 'errors': len(rows) - len(ok),
        'ratio': _stats(r['ratio'] for r in ok),
        'ratio_braked': _stats(r['ratio'] for r in braked),
        'greedy_ratio': _stats(r['greedy_ratio'] for r in ok),
        'floor_ratio': _stats(r['floor_ratio'] for r in ok),
        'floor_ratio_braked': _stats(r['floor_ratio'] for r in braked),
        'jerk_floor_above_reference': sum(1 for r in ok
                                          if r['jerk_floor'] > r['reference']['duration']),
        'rest_share': (len(ok) - len(braked)) / len(ok) if ok else None,
        'duration_s': _stats(r['duration'] for r in ok),
        'reference_s': _stats(r['reference']['duration'] for r in ok),
        'travel_m': _stats(r['travel'] for r in ok),
        'reference_travel_m': _stats(r['reference']['travel'] for r in ok),
        'travel_ratio': _stats(r['travel'] / r['reference']['travel'] for r in ok
                               if r['reference']['travel'] > 0),
        'hold_ratio': _stats(r['hold_ratio'] for r in ok),
        'ms': {k: _stats((r['ms'][k] for r in ok), 'p99') for k in ('stop', 'verify', 'total')},
        'reference_later_than_rest': sum(
            1 for r in ok if r['reference']['duration'] > r['rest_of_move'] + 1e-9),
        'greedy_later_than_rest': sum(
            1 for r in ok if r['reference']['greedy_duration'] > r['rest_of_move'] + 1e-9),
        'target_met': (bool(np.median([r['ratio'] for r in ok]) <= TARGET) if ok else None),
    }


def head_commit() -> str:
    """Return the commit checked out here, or an empty string outside git."""
    try:
        return subprocess.run(['git', '-C', str(HERE), 'rev-parse', 'HEAD'], check=True,
                              capture_output=True, text=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ''


def _line(name: str, s: dict) -> str:
    """Return one line of the table (its name alone where it has no stop)."""
    if not s['ratio']:
        return f'{name:<32}no stop'
    ratio, braked, ms = s['ratio'], s['ratio_braked'], s['ms']['total']
    return (f"{name:<32}{ratio['median']:>7.3f}{ratio['p90']:>7.3f}{ratio['max']:>7.3f}"
            f"{braked.get('median', float('nan')):>8.3f}{braked.get('max', float('nan')):>7.3f}"
            f"{s['rest_share']:>6.2f}{s['travel_m']['median']:>8.3f}"
            f"{s['reference_travel_m']['median']:>8.3f}{s['hold_ratio']['median']:>7.2f}"
            f"{s['hold_ratio']['max']:>7.2f}{ms['median']:>7.1f}{ms['p99']:>7.1f}"
            f"{ms['max']:>7.1f}")


def written(path: Path, benchmark: str, results: dict) -> None:
    """Write a benchmark's results as JSON, with the machine and commit they come from."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({
        'benchmark': benchmark,
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version(),
                    'platform': platform.platform(), 'commit': head_commit()},
        **results}, indent=1) + '\n')
    print(f'written {path}', file=sys.stderr)


def arguments(doc: str, moments: int, budget: bool = False):
    """
    Return the command line of a benchmark of moves changed in motion (``--moments``).

    ``budget``: it takes ``--budget S`` too (s of optimisation per request, as the node's).
    """
    parser = argparse.ArgumentParser(description=doc.split('\n')[1])
    parser.add_argument('--moments', type=int, default=moments, help='moments per move')
    parser.add_argument('--moves', type=int, default=None, help='only the first N moves')
    if budget:
        parser.add_argument('--budget', type=float, default=None,
                            help="s of optimisation per request, within the node's "
                            'planning.timeout, as the node answers (default: unbudgeted)')
    return parser.parse_args()


def main() -> int:
    """Run the benchmark."""
    args = arguments(__doc__, 20)
    cell = Cell.from_yaml(default_cell_path())
    robot = cell.robot
    checks = check_constant_bounds(robot)
    print(f"check, constant bounds: {checks['line_stop_s']:.6f} s against v / a "
          f"{checks['v_over_a_s']:.6f} s", file=sys.stderr)
    assert abs(checks['difference_s']) < 1e-6 and abs(checks['best_s'] - checks['v_over_a_s']) \
        < 1e-6, checks
    planner = Planner(cell, load_or_build(cell).roadmap, PlannerSettings(method=WholeCurve))
    warm = planner.plan('loadport2', 'loadlock2')  # warm-up: imports, caches, kernels
    planner.stop(warm.trajectory, 0.5 * warm.trajectory.duration, 'warm-up')
    rows, summaries = [], {}
    for kind, start, goal in moves_of(cell)[:args.moves]:
        name = f'{start}->{goal}'
        try:
            planned = planner.plan(start, goal)
        except PlanningError as exc:
            rows.append({'kind': kind, 'from': start, 'to': goal,
                         'error': f'{exc.code.name}: {exc.message}'})
            print(f'{name}: {exc.code.name}', file=sys.stderr)
            continue
        move = planned.trajectory
        duration = move.duration
        moments = [k * duration / (args.moments + 1) for k in range(1, args.moments + 1)]
        grid = path_grid(duration, moments)
        began = time.perf_counter()
        table = (grid,) + stage_rows(TailPath(move, 0.0), grid, robot)[:3]
        rows_ms = 1e3 * (time.perf_counter() - began)
        mine = []
        for k, at in enumerate(moments, 1):
            row = {'kind': kind, 'from': start, 'to': goal, 'duration_of_move': duration,
                   'moment': k, 'rows_ms': rows_ms}
            row.update(stop_row(planner, move, at, table, f'{name} ({k}/{args.moments + 1})',
                                planned.verification))
            mine.append(row)
        rows += mine
        summaries[name] = summary_of(mine)
        print(_line(name, summaries[name]), file=sys.stderr, flush=True)
    overall = {kind: summary_of([r for r in rows if 'moment' in r and kind in ('all', r['kind'])])
               for kind in ('station', 'port', 'all')}
    print(f"{'move':<32}{'ratio':>7}{'p90':>7}{'max':>7}{'braked':>8}{'max':>7}{'rest':>6}"
          f"{'travel':>8}{'ref':>8}{'hold':>7}{'max':>7}{'ms':>7}{'p99':>7}{'max':>7}")
    for name, s in list(summaries.items()) + [(f'[{k}]', s) for k, s in overall.items()]:
        print(_line(name, s))
    s = overall['all']
    print(f"ours / reference median {s['ratio']['median']:.3f} (target <= {TARGET}: "
          f"{'met' if s['target_met'] else 'not met'}); against braking hardest from the "
          f"start {s['greedy_ratio']['median']:.3f}; over the larger of it and the jerk "
          f"floor median {s['floor_ratio']['median']:.3f} (braked "
          f"{s['floor_ratio_braked']['median']:.3f}); 'rest' {s['rest_share']:.1%}; "
          f"errors {s['errors']}")
    written(RESULTS, 'controlled stops on the default cell (roadmap seed 0, whole-curve, '
            'loaded) against the time-optimal stop on the same path without jerk',
            {'grid_s': GRID, 'moments_per_move': args.moments, 'target': TARGET,
             'checks': checks, 'summary': overall, 'moves': summaries, 'rows': rows})
    return 0


if __name__ == '__main__':
    sys.exit(main())
