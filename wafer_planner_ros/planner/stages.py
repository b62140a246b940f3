"""
The stages of a plan, each timed: what an answer's ``timings_ms`` holds, and the deadline.

A request's time is split over ``STAGES`` (plus the optimisers' own ``stopwatch.PARTS``) so
that a slow answer says where its time went; a request past its deadline stops at the next
stage boundary with TIMEOUT.
"""

import time
from typing import Optional

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.trajectory.stopwatch import PARTS

STAGES = ('connect', 'search', 'corridor', 'spline', 'optimise', 'verify', 'stopping')
"""The stages of a plan, timed in its ``timings_ms`` (with ``PARTS`` of them and ``total``).
Of a move through a port: ``corridor`` its ways through the ports (their bounds and free
ends), ``stopping`` its transfer planned at rest between the port mouths
(``Planner.transfer``), ``optimise`` the transfer blended into the ways
(``CurveMethod.blend``), ``verify`` the moves checked whole."""


def stage_totals() -> dict:
    """Return every stage's and part's milliseconds, all zero: a plan's running totals."""
    return dict.fromkeys(STAGES + PARTS, 0.0)


def with_total(stage_ms: dict, begun: float) -> dict:
    """Return the stage totals with ``total``: ms since ``begun`` (``time.perf_counter``)."""
    return dict(stage_ms, total=(time.perf_counter() - begun) * 1000.0)


class Clock:
    """Add the time since the last lap to a named stage."""

    def __init__(self, totals: dict):
        """Start timing into ``totals`` (``stage_totals``)."""
        self.totals = totals
        self.last = time.perf_counter()

    def lap(self, stage: str) -> None:
        """Add the time since the previous call (or since the clock began) to ``stage``."""
        now = time.perf_counter()
        self.totals[stage] += (now - self.last) * 1000.0
        self.last = now


def check_deadline(deadline: Optional[float]) -> None:
    """Raise TIMEOUT when ``deadline`` (a ``time.monotonic()`` instant) has passed."""
    if deadline is not None and time.monotonic() > deadline:
        raise PlanningError(ErrorCode.TIMEOUT, 'planning did not finish before its deadline')
