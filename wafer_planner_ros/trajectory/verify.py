"""
Verification of a trajectory before it leaves the planner, whatever made it.

First the curve must be well formed (``Trajectory.ill_formed``: finite, consistent data,
exactly at the start and goal and at rest there); an ill-formed one fails at once and is
evaluated no further. Then it must be proven collision-free and within every port's
tolerances (``proof.prove`` in the cell's ``motion_model``: no sampling step) over all of
[0, T]. As a second, independent line, limits and the port tolerances (the wafer's offset
from a port's axis and the blade's angle from its heading while the wafer is inside it,
``geometry.ports``) are checked every
``LIMIT_STEP`` seconds from 0 to T and collisions at configurations no more than
``COLLISION_STEP`` rad apart in any joint, from 0 to T: on each eighth of a piece
(``Trajectory.pieces``) the time step between collision checks is ``COLLISION_STEP`` over
the exact peak joint speed there. Also checked: the start and goal are hit exactly, and
velocity and acceleration are zero at both ends (at the start, for a curve that continues a
motion, those of that motion). Every figure that is NaN is a problem:
a comparison with NaN never passes.

A curve that follows a verified curve's path under a timing of its own (a controlled stop,
``retimed.Retimed``) passes through none but that curve's configurations: its well-formed
check holds its time on the base's and never moving back. Given the verification the base
passed (``base``), what depends on the configurations alone (the proof, the collision
checks, the ports' tolerances) holds as it did for the base and is not done again; the
limits, which the timing changes, and the ends are checked as for any curve.
"""

from dataclasses import dataclass, field
from typing import Mapping, Optional, Tuple

import numpy as np

from wafer_planner_ros.geometry.ports import describe_deviation
from wafer_planner_ros.trajectory.constraints import limit_constraints, position_bound
from wafer_planner_ros.trajectory.constraints import state_ratios, States
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.proof import CurveProof, DEFAULT_MAX_DEPTH, prove
from wafer_planner_ros.trajectory.retimed import Retimed

LIMIT_STEP = 1e-3      # s
COLLISION_STEP = 1e-3  # rad
END_TOLERANCE = 1e-9   # rad/s, rad/s^2: "zero" at the ends, up to rounding
SAME_START = 1e-12     # s: two phase starts that differ by rounding only


@dataclass(frozen=True)
class Verification:
    """What the dense check found."""

    problems: Tuple[str, ...]
    """Human-readable failures; empty when the trajectory is good."""
    ratios: Mapping[str, float] = field(default_factory=dict)
    """Largest |value| / limit of each limit (<= 1 passes)."""
    min_clearance: float = np.inf
    """Smallest distance from the robot to a wall or obstacle along the motion (m)."""
    peak_jerk: Tuple[float, ...] = ()
    """Largest |jerk| of each joint (rad/s^3)."""
    peak_wafer_jerk: float = 0.0
    """Largest |jerk| of the wafer centre (m/s^3), what makes a wafer slide."""
    port_ratios: Mapping[str, float] = field(default_factory=dict)
    """While the wafer is inside a port, its largest offset from the axis ('lateral') and
    angle from the heading ('heading') over the port's tolerance (<= 1 passes; 0 when the
    wafer never enters a port)."""
    limit_samples: int = 0
    collision_samples: int = 0
    proof: Optional[CurveProof] = None
    """The proof that the curve is collision-free (None only if it was not attempted)."""
    on_base: bool = False
    """Whether the proof, the clearance and the port figures are those of the verified
    curve whose path this one follows (``verify``'s ``base``): its configurations are
    among that curve's, so its clearance is at least that one's."""

    @property
    def ok(self) -> bool:
        """Return whether the trajectory passed."""
        return not self.problems

    @property
    def proven(self) -> bool:
        """Return whether it passed with its path proven: a path another curve may follow."""
        return self.ok and self.proof is not None and self.proof.certified


def verify(trajectory: Trajectory, cell, start: np.ndarray, goal: np.ndarray,
           moving: Optional[Tuple[np.ndarray, np.ndarray]] = None,
           base: Optional['Verification'] = None) -> Verification:
    """
    Check a trajectory of ``cell``'s robot from start to goal.

    ``moving``: the velocity and acceleration it must start with, for a curve that
    continues a motion (a controlled stop); None: it starts at rest. ``base``: for a
    ``Retimed`` curve, the verification its base passed when the caller made or answered
    it (held since, never read back from a file): its configurations are not checked
    again (the module).
    """
    if base is not None and not (isinstance(trajectory, Retimed) and base.proven):
        raise ValueError('a verification to follow is given for a curve that follows no '
                         'verified path')
    problem = trajectory.ill_formed(start, goal)
    if problem is not None:
        return Verification(problems=(f'ill-formed curve: {problem}',))
    robot = cell.robot
    states = limit_states(trajectory, robot)
    t, q, qd, qdd = states.t, *states.derivatives[:3]
    problems, ratios, peak_jerk, peak_wafer_jerk = _limit_problems(states, robot)
    problems += _end_problems(start, goal, moving, q[[0, -1]], qd[[0, -1]], qdd[[0, -1]])
    if base is not None:
        return Verification(problems=tuple(problems), ratios=ratios,
                            min_clearance=base.min_clearance, peak_jerk=peak_jerk,
                            peak_wafer_jerk=peak_wafer_jerk, port_ratios=base.port_ratios,
                            limit_samples=len(t), proof=base.proof, on_base=True)
    port_ratios, breach = port_deviation(cell.port_model, q)
    problems += [f'the wafer inside a port reaches {ratio:.4f} x its {name} tolerance'
                 f'{breach}' for name, ratio in port_ratios.items() if not ratio <= 1.0]
    motion = cell.motion_model
    proof = prove(trajectory, motion, motion.lipschitz)
    if not proof.certified:
        problems.append("the curve is not proven collision-free and within the ports' "
                        'tolerances: ' + (
                            f'{motion.body_names[proof.body]} at t = {proof.collision:.4f} s'
                            if proof.collision is not None else
                            f'{len(proof.unproven)} pieces still open after '
                            f'{DEFAULT_MAX_DEPTH} splits'))
    # The model's bodies are grown by the clearance margin: <= 0 is closer than the margin.
    clearance, checks = dense_clearance(trajectory, cell.clearance_model)
    distance = clearance + robot.clearance_margin
    if not clearance > 0.0:
        problems.append(f'collision (clearance {distance * 1000:.2f} mm' + (
            f', margin {robot.clearance_margin * 1000:.2f} mm)'
            if robot.clearance_margin else ')'))
    return Verification(problems=tuple(problems), ratios=ratios, min_clearance=distance,
                        peak_jerk=peak_jerk, peak_wafer_jerk=peak_wafer_jerk,
                        port_ratios=port_ratios, limit_samples=len(t),
                        collision_samples=checks, proof=proof)


def verify_joined(trajectory: Retimed, cell, start: np.ndarray, goal: np.ndarray,
                  moving: Tuple[np.ndarray, np.ndarray], base: 'Verification', coast: float,
                  then: Tuple[Trajectory, 'Verification']) -> Verification:
    """
    Check a curve that follows its base for ``coast`` s, then goes on as a verified stop does.

    ``trajectory``: a ``Retimed`` of a curve that passed ``base`` (as ``verify``'s),
    sigma = t for its first ``coast`` s; from there exactly the curve of ``then``, a stop
    of the same base from the state reached, which passed its own verification (with
    ``base``) when it was made. So that part is not checked again. This checks the whole
    curve's timing (``Retimed.timing_problem``: sigma never moving back, on the base's
    time, at rest at the end; the base's own form was checked when it passed ``base``),
    that from ``coast`` on its timing is ``then``'s phases exactly (later by ``coast``),
    its ends as ``verify`` does, its limits over [0, ``coast``] every ``LIMIT_STEP``
    from 0, and that it joins ``then``'s curve in position, velocity and acceleration
    and ends where that does (to ``END_TOLERANCE``); its figures are the larger of the
    two parts'.
    """
    robot, (curve, rest) = cell.robot, then
    if not (isinstance(trajectory, Retimed) and isinstance(curve, Retimed) and
            curve.base is trajectory.base and base.proven and rest.ok and rest.on_base):
        raise ValueError('a joined verification needs a curve retimed along a verified path '
                         'and a verified stop made along it')
    # The base's form was checked when it passed ``base``; the ends are checked below.
    problem = trajectory.timing_problem() or \
        _goes_on_as(trajectory.timing, curve.timing, coast)
    if problem is not None:
        return Verification(problems=(f'ill-formed curve: {problem}',))
    t = limit_times(coast)
    # The limit check's times, then the join and the end: one evaluation.
    every = trajectory.evaluate_orders(np.append(t, [coast, trajectory.duration]), range(4))
    q, qd, qdd, qddd = (x[:-2] for x in every)
    states = States(t, q, qd, qdd, qddd, robot.arm.wafer_acceleration(q, qd, qdd))
    problems, ratios, peak_jerk, peak_wafer_jerk = _limit_problems(states, robot)
    problems += _end_problems(start, goal, moving, *(x[[0, -1]] for x in every[:3]))
    its = np.stack(curve.evaluate_orders([0.0, curve.duration], range(3)))
    gap = np.abs(np.stack(every[:3])[:, -2] - its[:, 0]).max()
    if not gap <= END_TOLERANCE:
        problems.append(f'it leaves its base {gap:.3g} from the verified stop it joins')
    gap = np.abs(every[0][-1] - its[0, 1]).max()
    if not gap <= END_TOLERANCE:
        problems.append(f'it ends {gap:.3g} from where the verified stop it joins ends')
    return Verification(
        problems=tuple(problems),
        ratios={name: max(ratio, rest.ratios.get(name, 0.0)) for name, ratio in ratios.items()},
        min_clearance=base.min_clearance,
        peak_jerk=tuple(np.maximum(peak_jerk, rest.peak_jerk).tolist()),
        peak_wafer_jerk=max(peak_wafer_jerk, rest.peak_wafer_jerk),
        port_ratios=base.port_ratios, limit_samples=len(t) + rest.limit_samples,
        proof=base.proof, on_base=True)


def _goes_on_as(timing, then, coast: float) -> Optional[str]:
    """
    Return how ``timing`` from ``coast`` on is not ``then``'s phases, later by ``coast``.

    The same jerks and phase states exactly, the phase starts to ``SAME_START`` s: then the
    two curves on one base are the same motion from there.
    """
    k = len(timing.jerks) - len(then.jerks)
    if k < 1 or not (np.array_equal(timing.jerks[k:], then.jerks) and
                     np.array_equal(timing.states[k:], then.states) and
                     np.abs(timing.starts[k:] - coast - then.starts).max() <= SAME_START):
        return f'it does not go on from {coast:.6g} s as the verified stop it joins'
    return None


def _limit_problems(states: States, robot) -> tuple:
    """Return (problems, ratios, peak jerk per joint, peak wafer jerk) of limit states."""
    constraints = limit_constraints(robot.limit_set)
    q, qd, qdd, qddd = states.derivatives
    ratios = state_ratios(constraints, states)
    # Written so that NaN fails: every comparison with NaN is false.
    problems = [f'{name} reaches {ratio:.4f} x its limit'
                for name, ratio in ratios.items() if not ratio <= 1.0]
    for name, values in (('position', q), ('velocity', qd), ('acceleration', qdd),
                         ('jerk', qddd)):
        if not np.isfinite(values).all():
            problems.append(f'the {name} is not finite everywhere')
    outside = position_bound(constraints).outside(q)
    problems += [f'joint {robot.joint_names[j]} leaves its position limits' for j in outside]
    peak_jerk = tuple(np.abs(qddd).max(axis=0).tolist())
    peak_wafer_jerk = float(np.hypot(*robot.arm.wafer_jerk(q, qd, qdd, qddd).T).max())
    return problems, ratios, peak_jerk, peak_wafer_jerk


def _end_problems(start, goal, moving, q, qd, qdd) -> list:
    """
    Return what is wrong with a curve's ends: ``q``, ``qd``, ``qdd`` at its start and end.

    Exactly at ``start`` and ``goal``, at rest at the end, starting at rest or, for a curve
    continuing a motion, in ``moving`` (velocity, acceleration).
    """
    problems = []
    if not np.array_equal(q[0], start) or not np.array_equal(q[-1], goal):
        problems.append('the trajectory does not start and end exactly at start and goal')
    ends = np.abs(np.concatenate([qd[[-1]], qdd[[-1]]])).max()
    if not ends <= END_TOLERANCE:
        problems.append(f'velocity or acceleration at the end is {ends:.3g}, not zero')
    begins = np.zeros((2, len(start))) if moving is None else np.asarray(moving, float)
    gap = np.abs(np.stack([qd[0], qdd[0]]) - begins).max()
    if not gap <= END_TOLERANCE:
        problems.append(f'velocity or acceleration at the start is {gap:.3g} from '
                        + ('zero' if moving is None else 'the motion it continues'))
    return problems


def port_deviation(model, q: np.ndarray) -> tuple:
    """
    Return ({'lateral': ratio, 'heading': ratio}, how the worst breaks a rule or '').

    Each ratio: the largest offset from a port's axis (angle from its heading) of the
    configurations ``q`` whose wafer is inside that port, over its tolerance; 0 when none is.
    """
    where, offset, turn = model.deviation(q)
    lateral, heading = np.zeros(len(q)), np.zeros(len(q))
    for k, port in enumerate(model.ports):
        at = where == k
        lateral[at] = offset[at] / port.lateral_tolerance
        heading[at] = turn[at] / port.heading_tolerance
    if not len(q):
        return {'lateral': 0.0, 'heading': 0.0}, ''
    ratios = {'lateral': float(lateral.max()), 'heading': float(heading.max())}
    worst = int(np.argmax(np.fmax(lateral, heading)))
    told = describe_deviation(model, q[worst:worst + 1])
    return ratios, '' if told is None else f' ({told})'


def dense_clearance(trajectory: Trajectory, model) -> tuple:
    """Return (smallest clearance, checks) at the times of ``collision_times``."""
    q = trajectory.evaluate(collision_times(trajectory))
    return float(model.clearance(q).min()), len(q)


def steps(counts: np.ndarray) -> np.ndarray:
    """Return 0, 1, ..., n - 1 for each count n of ``counts``, one after the other."""
    return np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)


def collision_times(trajectory: Trajectory) -> np.ndarray:
    """
    Return check times such that no joint moves more than COLLISION_STEP between two.

    The curve is cut into pieces on which the exact peak joint speed is known
    (``Trajectory.pieces``); checks on a piece are ``COLLISION_STEP / that peak``
    seconds apart. The first and last times are 0 and the duration.
    """
    boundaries, peaks = trajectory.pieces()
    # A piece whose speed is not finite fails verification anyway (and its configurations
    # count as colliding): one check is enough there, not a count cast from NaN.
    peaks = np.where(np.isfinite(peaks), peaks, 0.0)
    lengths = np.diff(boundaries)
    counts = np.maximum(np.ceil(lengths * peaks.max(axis=1) / COLLISION_STEP).astype(int), 1)
    offsets = steps(counts)
    t = np.repeat(boundaries[:-1], counts) + offsets * np.repeat(lengths / counts, counts)
    return np.append(t, trajectory.duration)


def limit_times(duration: float, step: float = LIMIT_STEP) -> np.ndarray:
    """Return the times of the limit check: 0 to ``duration``, at most ``step`` apart."""
    return np.linspace(0.0, duration, int(np.ceil(duration / step)) + 1)


def limit_states(trajectory: Trajectory, robot, step: float = LIMIT_STEP) -> States:
    """Return the curve's states (with the wafer acceleration) at the ``limit_times``."""
    t = limit_times(trajectory.duration, step)
    q, qd, qdd, qddd = trajectory.evaluate_orders(t, range(4))
    return States(t, q, qd, qdd, qddd, robot.arm.wafer_acceleration(q, qd, qdd))


def limit_ratios(trajectory: Trajectory, robot, constraints=None,
                 step: float = LIMIT_STEP) -> dict:
    """
    Return the largest |value| / limit of each limit, exactly as ``verify`` finds them.

    The same check times, the same values: a curve whose ratios here are all <= 1 passes
    the verification's limit check. ``constraints``: the limits (default: those of
    ``robot``'s set in use, ``limit_constraints``).
    """
    if constraints is None:
        constraints = limit_constraints(robot.limit_set)
    return state_ratios(constraints, limit_states(trajectory, robot, step))
