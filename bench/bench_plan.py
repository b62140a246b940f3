"""
Benchmark: planning latency and cycle time on the default cell, against TOPP-RA.

For every directed loadport/loadlock pair and for random free start/goal pairs: planning
latency (total and per stage), cycle time, the λ-scaled (paper start point) cycle time, and
the ratio of our cycle time to the time-optimal timing of *the same final curve* under the
same limits computed by TOPP-RA (our B-spline wrapped as its path, 2000+ grid points,
ParametrizeConstAccel, joint velocity/acceleration limits and the wafer limit as a
second-order constraint). TOPP-RA's own trajectory is checked densely and its worst limit
ratio reported. Prints a table; writes ``bench/results/plan.json``.
Usage: ``make bench`` or ``python bench/bench_plan.py [--random 200]``.
"""

import argparse
import json
import os
from pathlib import Path
import platform
import sys
import time

import numpy as np
import toppra
import toppra.algorithm
import toppra.constraint as tc

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner import Planner, STAGES
from wafer_planner_ros.roadmap.cache import load_or_build

RESULTS = Path(__file__).resolve().parent / 'results' / 'plan.json'
GRID = 2001


class CurvePath(toppra.interpolator.AbstractGeometricPath):
    """Our curve q(s), s in [0, T], as TOPP-RA's geometric path."""

    def __init__(self, trajectory):
        """Wrap a planner trajectory (``trajectory.curve.Trajectory``)."""
        self.trajectory = trajectory

    def __call__(self, s, order=0):
        """Return the path or its derivative at s."""
        scalar = np.isscalar(s)
        out = self.trajectory.evaluate(np.atleast_1d(s), order)
        return out[0] if scalar else out

    @property
    def dof(self):
        """Return the number of joints."""
        return 3

    @property
    def path_interval(self):
        """Return the parameter range."""
        return np.array([0.0, self.trajectory.duration])

    @property
    def waypoints(self):
        """Return nothing: the path is a curve."""
        return None


def toppra_time(cell, trajectory) -> dict:
    """Return TOPP-RA's time-optimal duration of the curve, and its own limit ratios."""
    robot = cell.robot
    arm, limit = robot.arm, robot.wafer_limit.xy
    constraints = [
        tc.JointVelocityConstraint(np.column_stack([-robot.limits.velocity,
                                                    robot.limits.velocity])),
        tc.JointAccelerationConstraint(np.column_stack([-robot.limits.acceleration,
                                                        robot.limits.acceleration])),
        tc.SecondOrderConstraint(
            lambda q, qd, qdd: arm.wafer_acceleration(q, qd, qdd),
            lambda q: np.vstack([np.eye(2), -np.eye(2)]),
            lambda q: np.concatenate([limit, limit]), dof=3),
    ]
    started = time.perf_counter()
    solver = toppra.algorithm.TOPPRA(constraints, CurvePath(trajectory),
                                     gridpoints=np.linspace(0.0, trajectory.duration, GRID),
                                     parametrizer='ParametrizeConstAccel')
    timed = solver.compute_trajectory()
    seconds = time.perf_counter() - started
    if timed is None:
        return {'duration': None, 'seconds': seconds}
    t = np.linspace(0.0, timed.duration, 20001)
    q, qd, qdd = timed(t), timed(t, 1), timed(t, 2)
    wafer = arm.wafer_acceleration(q, qd, qdd)
    return {'duration': float(timed.duration), 'seconds': seconds,
            'velocity_ratio': float(np.max(np.abs(qd) / robot.limits.velocity)),
            'acceleration_ratio': float(np.max(np.abs(qdd) / robot.limits.acceleration)),
            'wafer_ratio': float(np.max(np.abs(wafer) / limit))}


def random_pairs(cell, count: int, seed: int = 2026) -> list:
    """Return random free start/goal configurations (clearance above 5 mm)."""
    rng = np.random.default_rng(seed)
    limits = cell.robot.limits.position
    q = rng.uniform(limits[:, 0], limits[:, 1], (40 * count, 3))
    q = q[cell.clearance_model.clearance(q) > 0.005][:2 * count]
    return [(a, b) for a, b in zip(q[::2], q[1::2])]


def _stats(values) -> dict:
    values = np.asarray([v for v in values if v is not None], float)
    if not len(values):
        return {}
    return {'median': float(np.median(values)), 'p99': float(np.percentile(values, 99)),
            'max': float(values.max()), 'mean': float(values.mean()), 'n': len(values)}


def main() -> int:
    """Run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--random', type=int, default=200, help='random start/goal pairs')
    args = parser.parse_args()
    cell = Cell.from_yaml(default_cell_path())
    planner = Planner(cell, load_or_build(cell).roadmap)
    planner.plan('loadport2', 'loadlock2')  # warm-up: imports, caches
    requests = [('station', a, b) for a, b in station_pairs(cell)]
    requests += [('random', a, b) for a, b in random_pairs(cell, args.random)]
    rows = []
    for index, (kind, start, goal) in enumerate(requests):
        row = {'kind': kind, 'from': start if kind == 'station' else np.round(start, 4).tolist(),
               'to': goal if kind == 'station' else np.round(goal, 4).tolist()}
        try:
            result = planner.plan(start, goal)
        except PlanningError as exc:
            row.update(status=exc.code.value, message=exc.message)
            rows.append(row)
            continue
        reference = toppra_time(cell, result.trajectory)
        row.update(status='ok', cycle_time=result.cycle_time,
                   initial_cycle_time=result.initial_cycle_time,
                   optimised=result.metrics['optimised'], timings_ms=dict(result.timings_ms),
                   candidates=result.metrics['candidates'], toppra=reference,
                   toppra_ratio=(result.cycle_time / reference['duration']
                                 if reference['duration'] else None))
        rows.append(row)
        if index % 20 == 0:
            print(f'{index + 1}/{len(requests)}', file=sys.stderr)
    ok = [r for r in rows if r['status'] == 'ok']
    summary = {}
    for kind in ('station', 'random', 'all'):
        mine = [r for r in ok if kind in ('all', r['kind'])]
        summary[kind] = {
            'requests': sum(1 for r in rows if kind in ('all', r['kind'])),
            'ok': len(mine),
            'latency_ms': _stats(r['timings_ms']['total'] for r in mine),
            'stage_ms': {s: _stats(r['timings_ms'][s] for r in mine) for s in STAGES},
            'cycle_time_s': _stats(r['cycle_time'] for r in mine),
            'initial_cycle_time_s': _stats(r['initial_cycle_time'] for r in mine),
            'toppra_ratio': _stats(r['toppra_ratio'] for r in mine),
            'toppra_worst_wafer_ratio': max((r['toppra'].get('wafer_ratio', 0) for r in mine),
                                            default=None),
            'fell_back': sum(1 for r in mine if not r['optimised']),
        }
    print(f"{'pair':<22}{'cycle s':>8}{'λ-scaled':>9}{'TOPP-RA':>8}{'ratio':>7}{'ms':>8}")
    for r in ok:
        if r['kind'] == 'station':
            print(f"{r['from'] + '->' + r['to']:<22}{r['cycle_time']:>8.3f}"
                  f"{r['initial_cycle_time']:>9.3f}{r['toppra']['duration']:>8.3f}"
                  f"{r['toppra_ratio']:>7.3f}{r['timings_ms']['total']:>8.1f}")
    for kind, s in summary.items():
        lat, ratio = s['latency_ms'], s['toppra_ratio']
        print(f"{kind:<8} ok {s['ok']}/{s['requests']}  latency median {lat['median']:.1f} ms "
              f"p99 {lat['p99']:.1f} ms  cycle median {s['cycle_time_s']['median']:.3f} s "
              f"(λ-scaled {s['initial_cycle_time_s']['median']:.3f} s)  ours/TOPP-RA median "
              f"{ratio['median']:.3f} (max {ratio['max']:.3f})  fell back {s['fell_back']}")
        print('         stage medians ms: ' + ', '.join(
            f"{k} {v['median']:.1f}" for k, v in s['stage_ms'].items()))
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({
        'benchmark': 'planning on the default cell (1500-node roadmap, seed 0) vs TOPP-RA',
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version(),
                    'platform': platform.platform()},
        'summary': summary, 'rows': rows}, indent=1) + '\n')
    print(f'written {RESULTS}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
