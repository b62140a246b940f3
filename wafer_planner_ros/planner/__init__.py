"""
Planning one request on one cell, ROS-free: from its two ends to a verified trajectory.

Where a change belongs:

- ``pipeline``: ``Planner``, the entry point: resolves the ends, routes the request to the
  search or to a move through a port, keeps a planner per limit set and curve method.
- ``endpoints``: what a request's ends mean (stations, ``:inside`` poses, joint angles) and
  why one is refused.
- ``candidates``: the search over elbow-branch combinations (draft, give up, finish,
  verify, fall back).
- ``through``: moves into and out of ports (the ways through the ports and the transfer
  between their mouths, stopping or blended).
- ``legs``: what a planner keeps between requests (transfers, drafts, ways).
- ``optima``: the optima it answered, by their ends: drafts for requests near them.
- ``result``: ``PlanResult`` and ``answer``, the one place an answer is made.
- ``settings``: ``PlannerSettings``. ``stages``: the timed stages and the deadline.

Below it: ``trajectory`` (corridor, curve methods, verification), ``moves`` (the ways
through ports), ``roadmap`` (the path search). Above it: ``service`` (the request policy:
tables, budgets, adopting another limit set's curve).
"""

from wafer_planner_ros.planner.pipeline import Planner
from wafer_planner_ros.planner.result import answer, path_lengths, PlanResult
from wafer_planner_ros.planner.settings import PlannerSettings, SAMPLE_PERIOD_RANGE
from wafer_planner_ros.planner.stages import STAGES

__all__ = ['Planner', 'PlannerSettings', 'PlanResult', 'SAMPLE_PERIOD_RANGE', 'STAGES',
           'answer', 'path_lengths']
