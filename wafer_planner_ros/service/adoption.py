"""
Answering a request of one limit set with a curve planned against another, verified again.

The optimiser is local: an empty move's own optimum can come out slower than the loaded
move between the same poses, though the empty set has every freedom the loaded one has. A
curve planned against one limit set answers a request of another whenever it passes that
one's verification in full (every limit, the ports, the proof, the dense collision check),
forwards or backwards in time (a motion and its reverse meet the same limits). This is the
service's policy, used by the station table and the swap cycle; the planner plans.
"""

from dataclasses import replace
from typing import Optional

import numpy as np

from wafer_planner_ros.planner import Planner, PlanResult
from wafer_planner_ros.trajectory.verify import verify


def adopted(planner: Planner, other: PlanResult, backwards: bool = False
            ) -> Optional[PlanResult]:
    """
    Return another answer's motion as ``planner``'s answer if it passes its verification.

    ``backwards``: the motion reversed in time, from ``other``'s goal to its start. Its
    metrics say ``adopted`` (and ``reversed`` when it runs the other way to the answer it
    came from). None when it does not pass.
    """
    trajectory = other.trajectory.backwards() if backwards else other.trajectory
    start_q, goal_q = (other.goal_q, other.start_q) if backwards else \
        (other.start_q, other.goal_q)
    checked = verify(trajectory, planner.cell, start_q, goal_q)
    if not checked.ok:
        return None
    times, positions, velocities, accelerations = trajectory.samples(
        planner.settings.sample_period)
    order = slice(None, None, -1 if backwards else 1)
    return replace(
        other, start=other.goal if backwards else other.start,
        goal=other.start if backwards else other.goal, start_q=start_q, goal_q=goal_q,
        branches=tuple(other.branches[order]), load=planner.load, trajectory=trajectory,
        verification=checked, times=times, positions=positions, velocities=velocities,
        accelerations=accelerations, roadmap_path=np.asarray(other.roadmap_path)[order],
        path=np.asarray(other.path)[order],
        metrics=dict(other.metrics, adopted=True, branches=list(other.branches[order]))
        | ({'reversed': not other.metrics.get('reversed', False)} if backwards else {}))


def faster(planner: Planner, result: Optional[PlanResult], other: Optional[PlanResult],
           backwards: bool = False) -> Optional[PlanResult]:
    """
    Return ``result``, or ``other`` as ``planner``'s answer (``adopted``) if faster.

    ``other`` is taken when it is shorter than ``result`` (or ``result`` is None) and
    passes ``planner``'s verification; ``backwards``: ``other`` reversed in time.
    """
    if other is None or (result is not None and result.cycle_time <= other.cycle_time):
        return result
    return adopted(planner, other, backwards) or result
