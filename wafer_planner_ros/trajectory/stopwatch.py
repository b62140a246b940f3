"""
Where a plan's time goes: named parts of a stage timed while a caller collects them.

``collecting(totals)`` makes ``totals`` (ms by name) the place where every ``timed(name)``
block adds its time, in this thread and until it ends (a context variable); with nobody
collecting a block costs one lookup. The planner collects them into its result's
``timings_ms`` (``PARTS``): of the whole-curve optimisation, the quadratic subproblems
(``optimise.qp``), the constraint rows and their gradients (``optimise.rows``), the limits
met between samples after each solve (``optimise.limits``) and the collision proofs
(``optimise.proof``); the rest of ``optimise`` is the solver's own Python.
"""

import contextlib
import contextvars
import time
from typing import Dict, Iterator, Optional

PARTS = ('optimise.qp', 'optimise.rows', 'optimise.limits', 'optimise.proof')
"""The parts of the planner's stages that are timed (ms, within their stage's time)."""

_TOTALS: contextvars.ContextVar[Optional[Dict[str, float]]] = contextvars.ContextVar(
    'wafer_planner_stopwatch', default=None)


@contextlib.contextmanager
def collecting(totals: Dict[str, float]) -> Iterator[Dict[str, float]]:
    """Add every ``timed`` block's ms to ``totals`` while the body runs; yield ``totals``."""
    token = _TOTALS.set(totals)
    try:
        yield totals
    finally:
        _TOTALS.reset(token)


@contextlib.contextmanager
def timed(name: str) -> Iterator[None]:
    """Add the body's time (ms) to ``name`` of the totals being collected, if any."""
    totals = _TOTALS.get()
    if totals is None:
        yield
        return
    begun = time.perf_counter()
    try:
        yield
    finally:
        totals[name] = totals.get(name, 0.0) + (time.perf_counter() - begun) * 1000.0
