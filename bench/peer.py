"""
Benchmark peer: a MoveIt-style pipeline (OMPL PRM, simplification, cubic spline, TOPP-RA).

The pipeline the planner is compared with, on the same cells and limits:

1. OMPL's PRM in the 3-D joint space (the joint position limits as bounds), grown once per
   (cell, seed) to 1500 milestones by uniform sampling and reused for every query. A state is
   valid where ``cell.clearance_model`` reports a positive clearance; OMPL's discrete motion
   validator checks motions at steps of at most 5 mrad (Euclidean in joint space). A query
   adds its start and goal as milestones (connected to their nearest milestones by checked
   motions), then searches the roadmap; the roadmap is not grown while answering.
2. ``PathSimplifier.simplifyMax`` (shortcuts, B-spline smoothing, vertex reduction, run to
   convergence; not time-bounded, so runs repeat).
3. A clamped cubic spline through the simplified vertices, parameterised by normalised
   joint-space chord length, checked for collision at steps of at most 1 mrad in every joint;
   where it collides, the midpoints of the path segments that hold the colliding samples
   become vertices and the spline is refitted (at most MAX_REFITS times).
4. TOPP-RA (2001 grid points, constant acceleration between them) under the joint velocity
   and acceleration limits and the wafer acceleration limit on x and y, and on its magnitude
   when the cell sets one (a polygon inscribed in the circle of that radius).
5. The timed result sampled every 1 ms: joint velocity, acceleration, wafer acceleration and
   collision; where a limit is exceeded, time is stretched uniformly until none is (by the
   sampled excess, then, should the samples of the stretched motion still show some, by
   that and STRETCH_MARGIN more each time).

Station pairs are planned for every combination of the start's and the goal's elbow branches
and the fastest kept. Usage: ``python bench/peer.py [--seeds 1 2 3]``; prints a table per
cell and seed and writes ``bench/results/peer.json``.
"""

import argparse
import json
import os
from pathlib import Path
import platform
import sys
import time

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou
from scipy.interpolate import make_interp_spline
import toppra
import toppra.algorithm
import toppra.constraint as tc

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs

RESULTS = Path(__file__).resolve().parent / 'results' / 'peer.json'
TEST_CELLS = Path(__file__).resolve().parents[1] / 'test' / 'support' / 'cells'
MILESTONES = 1500
MOTION_STEP = 0.005
"""rad: the longest step of OMPL's motion checks (Euclidean in joint space)."""
CURVE_STEP = 0.001
"""rad: the longest step, in any joint, of the spline's collision check."""
MAX_REFITS = 30
"""Refits of the spline after which a curve that still collides is a failure."""
GRID = 2001
"""TOPP-RA's grid points."""
SAMPLE_PERIOD = 0.001
"""s: the period at which the timed result is checked."""
MAX_STRETCHES = 10
"""Uniform stretches after which a result still beyond a limit is a failure."""
STRETCH_MARGIN = 1e-3
"""The time a stretch after the first adds beyond the excess the samples show (relative)."""
TOLERANCE = 1e-9
"""The relative excess over a limit that is rounding, not a violation."""
NORM_FACETS = 32
"""Sides of the polygon that stands for the wafer acceleration's magnitude limit."""


class PeerFailure(Exception):
    """A stage of the pipeline failed; the message says which and why."""


class SplinePath(toppra.interpolator.AbstractGeometricPath):
    """A spline q(u), u in [0, 1], as TOPP-RA's geometric path."""

    def __init__(self, spline):
        """Wrap a scipy B-spline of the three joints."""
        self.spline = spline

    def __call__(self, s, order=0):
        """Return the path or its derivative at s."""
        return self.spline(s, order)

    @property
    def dof(self):
        """Return the number of joints."""
        return 3

    @property
    def path_interval(self):
        """Return the parameter range."""
        return np.array([0.0, 1.0])


class Peer:
    """The peer pipeline on one cell: a PRM built once, then any number of queries."""

    def __init__(self, cell, seed: int = 1, milestones: int = MILESTONES):
        """Build the PRM of the cell, OMPL seeded with ``seed``; time it (build_seconds)."""
        started = time.perf_counter()
        self.cell, self.seed, self.model = cell, seed, cell.clearance_model
        ou.setLogLevel(ou.LOG_WARN)  # OMPL informs on every query otherwise
        _seed_ompl(seed)
        self.space = ob.RealVectorStateSpace(3)
        bounds = ob.RealVectorBounds(3)
        for joint, (low, high) in enumerate(cell.robot.limits.position):
            bounds.setLow(joint, float(low))
            bounds.setHigh(joint, float(high))
        self.space.setBounds(bounds)
        self.si = ob.SpaceInformation(self.space)
        self.si.setStateValidityChecker(_validity(self.model))
        self.si.setStateValidityCheckingResolution(MOTION_STEP / self.space.getMaximumExtent())
        self.si.setup()
        self.problem = ob.ProblemDefinition(self.si)
        self.prm = og.PRM(self.si)
        self.prm.setProblemDefinition(self.problem)
        self.prm.setup()
        self.prm.growRoadmapPtc(ob.PlannerTerminationCondition(
            lambda: self.prm.milestoneCount() >= milestones))
        self.milestones, self.edges = self.prm.milestoneCount(), self.prm.edgeCount()
        self.simplifier = og.PathSimplifier(self.si)
        self.constraints = _constraints(cell.robot)
        self._start, self._goal = self.space.allocState(), self.space.allocState()
        self.build_seconds = time.perf_counter() - started

    def plan(self, start_q, goal_q) -> dict:
        """Plan from one configuration to another; return the result (duration None: failed)."""
        started = time.perf_counter()
        result = {'duration': None, 'planning_ms': None, 'peak_jerk': None, 'stretch': None,
                  'stretches': None, 'min_clearance': None, 'vertices': None, 'refits': None,
                  'ok': False, 'reason': None}
        try:
            vertices = self._query(np.asarray(start_q, float), np.asarray(goal_q, float))
            result['vertices'] = len(vertices)
            spline, result['refits'], curve_clearance = self._curve(vertices)
            solver = toppra.algorithm.TOPPRA(self.constraints, SplinePath(spline),
                                             gridpoints=np.linspace(0.0, 1.0, GRID),
                                             parametrizer='ParametrizeConstAccel')
            timed = solver.compute_trajectory()
            if timed is None:
                raise PeerFailure('TOPP-RA: no feasible parameterisation')
            checked = self._check(timed)
            result.update(checked, ok=True,
                          min_clearance=min(curve_clearance, checked['min_clearance']))
        except PeerFailure as exc:
            result['reason'] = str(exc)
        result['planning_ms'] = (time.perf_counter() - started) * 1000.0
        return result

    def plan_stations(self, start_name: str, goal_name: str) -> dict:
        """Plan every elbow combination of two stations; return the fastest, with all."""
        branches = []
        for start in self.cell.stations[start_name].configs:
            for goal in self.cell.stations[goal_name].configs:
                branch = self.plan(start.q, goal.q)
                branch['elbows'] = [start.elbow, goal.elbow]
                branches.append(branch)
        ok = [b for b in branches if b['ok']]
        if ok:
            best = dict(min(ok, key=lambda b: b['duration']))
        else:
            best = dict(branches[0], elbows=None, reason='; '.join(
                f"elbows {b['elbows']}: {b['reason']}" for b in branches))
        best['planning_ms'] = sum(b['planning_ms'] for b in branches)
        best['branches'] = branches
        return best

    def _query(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Return the vertices (V, 3) of the simplified roadmap path from start to goal."""
        for state, q in ((self._start, start), (self._goal, goal)):
            for joint in range(3):
                state[joint] = float(q[joint])
        self.problem.clearSolutionPaths()
        self.problem.setStartAndGoalStates(self._start, self._goal)
        self.prm.clearQuery()
        # A condition that has already fired: connect start and goal and search the roadmap,
        # but grow none of it. OMPL then files a path that reaches the goal as approximate
        # with difference 0, and one that does not as approximate with the gap left.
        status = self.prm.solve(ob.plannerAlwaysTerminatingCondition())
        if not self.problem.hasSolution():
            raise PeerFailure(f'PRM: {status}')
        path = self.problem.getSolutionPath()
        if np.max(np.abs(_vertices(path)[-1] - goal)) > 1e-12:
            raise PeerFailure('PRM: the roadmap does not connect start and goal')
        self.simplifier.simplifyMax(path)
        vertices = _vertices(path)
        keep = np.append(True, np.linalg.norm(np.diff(vertices, axis=0), axis=1) > 0.0)
        return vertices[keep]

    def _curve(self, vertices: np.ndarray) -> tuple:
        """Return the collision-free spline, the refits it took and its smallest clearance."""
        for refit in range(MAX_REFITS + 1):
            spline, knots = _fit(vertices)
            u, q = _dense(spline, CURVE_STEP)
            clearance = self.model.clearance(q)
            hit = clearance <= 0.0
            if not hit.any():
                return spline, refit, float(clearance.min())
            segments = np.unique(np.clip(np.searchsorted(knots, u[hit], side='right') - 1,
                                         0, len(vertices) - 2))
            midpoints = 0.5 * (vertices[segments] + vertices[segments + 1])
            vertices = np.insert(vertices, segments + 1, midpoints, axis=0)
        raise PeerFailure(f'spline: still in collision after {MAX_REFITS} refits')

    def _check(self, timed) -> dict:
        """Check TOPP-RA's result every SAMPLE_PERIOD, stretching time until it holds."""
        robot = self.cell.robot
        stretch = 1.0
        for stretches in range(MAX_STRETCHES + 1):
            duration = stretch * timed.duration
            uniform = np.arange(0.0, duration, SAMPLE_PERIOD)
            t = np.minimum(np.append(uniform, duration) / stretch, timed.duration)
            q, qd, qdd = timed(t), timed(t, 1) / stretch, timed(t, 2) / stretch ** 2
            wafer = robot.arm.wafer_acceleration(q, qd, qdd)
            first = np.max(np.abs(qd) / robot.limits.velocity)
            second = [np.max(np.abs(qdd) / robot.limits.acceleration),
                      np.max(np.abs(wafer) / robot.wafer_limit.xy)]
            if robot.wafer_limit.norm is not None:
                second.append(np.max(np.linalg.norm(wafer, axis=-1))
                              / robot.wafer_limit.norm)
            factor = max(first, np.sqrt(max(second)))  # velocity goes as 1/s, the rest 1/s^2
            if factor <= 1.0 + TOLERANCE:
                break
            # The first stretch removes the sampled excess exactly. The samples of the
            # stretched motion fall elsewhere on it and can show a little more: a margin
            # then makes every further stretch count.
            stretch *= factor * (1.0 + (STRETCH_MARGIN if stretches else 0.0))
        else:
            raise PeerFailure(f'check: still beyond a limit after {MAX_STRETCHES} stretches')
        clearance = self.model.clearance(q)
        if clearance.min() <= 0.0:
            raise PeerFailure('check: in collision at t = '
                              f'{stretch * t[np.argmin(clearance)]:.3f} s')
        jerk = np.abs(np.diff(qdd[:len(uniform)], axis=0)) / SAMPLE_PERIOD
        return {'duration': float(duration), 'stretch': float(stretch), 'stretches': stretches,
                'peak_jerk': jerk.max(axis=0).tolist(), 'min_clearance': float(clearance.min())}


def _seed_ompl(seed: int) -> None:
    """Seed OMPL's generator of seeds, from which every RNG made from now on draws its own."""
    # Seeding again in the same process works for the RNGs made afterwards (all of a Peer's
    # are), but OMPL logs it as an error: keep that quiet.
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(seed)
    ou.setLogLevel(level)


def _validity(model):
    """Return OMPL's state validity check: clearance above zero."""
    def valid(state) -> bool:
        return bool(model.clearance(np.array([[state[0], state[1], state[2]]]))[0] > 0.0)
    return valid


def _vertices(path) -> np.ndarray:
    """Return the states of an OMPL geometric path, (V, 3)."""
    return np.array([[state[j] for j in range(3)] for state in path.getStates()])


def _fit(vertices: np.ndarray) -> tuple:
    """Return the clamped cubic through the vertices and their normalised chord lengths."""
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(vertices, axis=0),
                                                            axis=1))])
    knots = chord / chord[-1]
    zeros = np.zeros(3)
    return make_interp_spline(knots, vertices, k=3,
                              bc_type=([(1, zeros)], [(1, zeros)])), knots


def _dense(spline, step: float) -> tuple:
    """Return samples u, q(u) of the spline no more than ``step`` apart in any joint."""
    count = 1001
    while True:
        u = np.linspace(0.0, 1.0, count)
        q = spline(u)
        largest = np.abs(np.diff(q, axis=0)).max()
        if largest <= step:
            return u, q
        count = int(np.ceil((count - 1) * largest / step * 1.05)) + 1


def _constraints(robot) -> list:
    """Return TOPP-RA's constraints: joint velocity and acceleration, wafer acceleration."""
    velocity, acceleration = robot.limits.velocity, robot.limits.acceleration
    normals = [np.eye(2), -np.eye(2)]
    bounds = [robot.wafer_limit.xy, robot.wafer_limit.xy]
    if robot.wafer_limit.norm is not None:
        angles = 2.0 * np.pi * np.arange(NORM_FACETS) / NORM_FACETS
        normals.append(np.column_stack([np.cos(angles), np.sin(angles)]))
        bounds.append(np.full(NORM_FACETS, robot.wafer_limit.norm
                              * np.cos(np.pi / NORM_FACETS)))
    facets, limits = np.vstack(normals), np.concatenate(bounds)
    arm = robot.arm
    return [
        tc.JointVelocityConstraint(np.column_stack([-velocity, velocity])),
        tc.JointAccelerationConstraint(np.column_stack([-acceleration, acceleration])),
        tc.SecondOrderConstraint(lambda q, qd, qdd: arm.wafer_acceleration(q, qd, qdd),
                                 lambda q: facets, lambda q: limits, dof=3),
    ]


def _run(cell, seed: int) -> dict:
    """Plan every station pair of a cell with a peer of the given seed; print the table."""
    peer = Peer(cell, seed)
    print(f'\n{cell.name}, seed {seed}: PRM {peer.milestones} milestones, {peer.edges} edges, '
          f'built in {peer.build_seconds:.1f} s')
    print(f"{'pair':<22}{'elbows':>8}{'s':>7}{'ms':>8}{'jerk rad/s^3 per joint':>26}"
          f"{'stretch':>9}{'verts':>6}{'refits':>7}")
    rows = []
    for start, goal in station_pairs(cell):
        row = {'from': start, 'to': goal, **peer.plan_stations(start, goal)}
        rows.append(row)
        pair = f'{start}->{goal}'
        if not row['ok']:
            print(f"{pair:<22} failed: {row['reason']}")
            continue
        jerk = ' '.join(f'{j:>8.0f}' for j in row['peak_jerk'])
        print(f"{pair:<22}{str(row['elbows']):>8}{row['duration']:>7.3f}"
              f"{row['planning_ms']:>8.0f}{jerk:>26}{row['stretch']:>9.5f}"
              f"{row['vertices']:>6}{row['refits']:>7}")
    durations = [r['duration'] for r in rows if r['ok']]
    queries = [b['planning_ms'] for r in rows for b in r['branches']]
    summary = {'cell': cell.name, 'seed': seed, 'build_seconds': peer.build_seconds,
               'milestones': peer.milestones, 'edges': peer.edges,
               'ok': len(durations), 'pairs': len(rows),
               'median_duration': float(np.median(durations)) if durations else None,
               'median_query_ms': float(np.median(queries))}
    print(f"median duration {summary['median_duration']:.3f} s over {len(durations)}/"
          f"{len(rows)} pairs; median query {summary['median_query_ms']:.0f} ms")
    return {**summary, 'rows': rows}


def main() -> int:
    """Run the peer on the default cell and the test cells."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seeds', type=int, nargs='+', default=[1], help="OMPL's seeds")
    args = parser.parse_args()
    cells = [Cell.from_yaml(path) for path in (default_cell_path(), TEST_CELLS / 'pillar.yaml',
                                               TEST_CELLS / 'notched.yaml')]
    print('s: duration; ms: planning, every elbow branch together; jerk: the largest |jerk| '
          'of the 1 ms samples\n(finite differences of acceleration); stretch: the uniform '
          'factor; verts: after simplification')
    runs = [_run(cell, seed) for cell in cells for seed in args.seeds]
    print('\nmedian duration per cell over its seeds')
    medians = {}
    for cell in cells:
        durations = [r['duration'] for run in runs if run['cell'] == cell.name
                     for r in run['rows'] if r['ok']]
        medians[cell.name] = float(np.median(durations)) if durations else None
        print(f'{cell.name:<16}{medians[cell.name]:.3f} s')
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({
        'benchmark': 'MoveIt-style peer: OMPL PRM, simplifyMax, clamped cubic, TOPP-RA',
        'settings': {'milestones': MILESTONES, 'motion_step_rad': MOTION_STEP,
                     'curve_step_rad': CURVE_STEP, 'max_refits': MAX_REFITS,
                     'toppra_grid': GRID, 'parametrizer': 'ParametrizeConstAccel',
                     'sample_period_s': SAMPLE_PERIOD, 'norm_facets': NORM_FACETS,
                     'peak_jerk': 'finite differences of the 1 ms acceleration samples',
                     'seeds': args.seeds},
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version(),
                    'platform': platform.platform()},
        'median_duration': medians, 'runs': runs}, indent=1) + '\n')
    print(f'written {RESULTS}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
