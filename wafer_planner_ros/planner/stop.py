"""
A controlled stop of a published move, answered like any request (``trajectory.stopping``).

``stop(planner, trajectory, at, label)`` brings ``trajectory`` to rest from ``at`` seconds
after its start, on its own path, as fast as the planner's limit set allows; the answer
starts exactly in the curve's state there (its velocity and acceleration included) and is
verified as every answer is, that start motion with it.
"""

import time

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner.endpoints import Endpoint
from wafer_planner_ros.planner.result import answer, PlanResult
from wafer_planner_ros.trajectory.stopping import controlled_stop, moving_state
from wafer_planner_ros.trajectory.verify import verify

METHOD = 'controlled-stop'
"""The method a stop's answer names."""


def stop(planner, trajectory, at: float, label: str) -> PlanResult:
    """
    Return the verified controlled stop of ``trajectory`` from ``at`` (the module).

    ``label``: what the stopped move is called in the answer (e.g. its request id). Raise
    PlanningError: OUTSIDE_TRAJECTORY or AT_REST (``stopping.moving_state``),
    VERIFICATION_FAILED if the stop fails its verification.
    """
    begun = time.perf_counter()
    q, qd, qdd = moving_state(trajectory, at)
    made = controlled_stop(trajectory, at, planner.cell.robot)
    curve = made.trajectory
    end = curve.evaluate([curve.duration])[0]
    checked = time.perf_counter()
    verification = verify(curve, planner.cell, q, end, moving=(qd, qdd))
    if not verification.ok:
        raise PlanningError(ErrorCode.VERIFICATION_FAILED,
                            f'the stop of {label} at {at:.6g} s failed its verification: '
                            + '; '.join(verification.problems))
    done = time.perf_counter()
    start = Endpoint(f'{label} at {at:.6g} s', ((None, q),))
    goal = Endpoint(f'{label} stopped', ((None, end),))
    return answer(planner, start, goal, q, end, (None, None), curve, curve.duration,
                  verification, q[None], q[None], {'stopped_at': float(at),
                                                   'share': made.share,
                                                   'timing': made.timing},
                  0, method=METHOD,
                  timings_ms={'stop': 1e3 * (checked - begun),
                              'verify': 1e3 * (done - checked),
                              'total': 1e3 * (done - begun)})
