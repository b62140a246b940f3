"""
Running variants on an executor into a study's results: retried once, progress shown.

A variant whose attempt fails (the evaluation raised, or its worker died) is tried once
more, on whichever worker is free; failing twice, it is recorded as ``failed`` with both
reasons, and the study goes on. Rows are added as they arrive (``Results.add``).
"""

import time
from typing import Callable, Iterable, Optional

from wafer_planner_ros import __version__
from wafer_planner_ros.study.evaluate import FAILED, PLANNED
from wafer_planner_ros.study.results import Results
from wafer_planner_ros.study.spec import Study, Variant

ATTEMPTS = 2
"""Tries a variant gets before it is recorded as failed."""


def payload(study: Study, variant: Variant) -> dict:
    """Return what a worker needs to evaluate ``variant`` (``evaluate.task``)."""
    return {'key': variant.key, 'index': variant.index, 'values': variant.values,
            'document': variant.document, 'nodes': study.nodes, 'seed': study.seed,
            'method': study.method, 'version': __version__}


def failed_row(variant: Variant, reasons: list) -> dict:
    """Return the row of a variant whose every attempt failed."""
    return {'variant': variant.key, 'index': variant.index,
            'parameters': dict(variant.values), 'status': FAILED,
            'reason': '; '.join(f'attempt {n}: {r}' for n, r in enumerate(reasons, 1))}


def run_variants(study: Study, variants: Iterable[Variant], executor, results: Results,
                 progress: Optional[Callable[[str], None]] = None,
                 on_row: Optional[Callable[[dict], None]] = None,
                 tags: Optional[dict] = None) -> int:
    """
    Evaluate ``variants`` on ``executor`` into ``results``; return how many were run.

    ``progress(text)``: called as each ends (and once at the start), with counts and the
    time left; ``on_row(row)``: called with each row once it is on disk; ``tags``: key ->
    fields added to that variant's row (a search's trial number).
    """
    waiting = [v for v in variants if v.key not in results.rows]
    by_key = {v.key: v for v in waiting}
    total, done, planned, started = len(waiting), 0, 0, time.monotonic()
    reasons = {v.key: [] for v in waiting}
    queue = list(reversed(waiting))

    def show() -> None:
        if progress is None:
            return
        if not total:
            progress('nothing to plan: every variant is in the results already')
            return
        running = total - done - len(queue)
        left = ''
        if done:
            seconds = (time.monotonic() - started) / done * (total - done)
            left = f', about {_clock(seconds)} left'
        progress(f'{done}/{total} variants ({planned} planned in full), {running} running'
                 f'{left}')

    def fill() -> None:
        while queue and executor.free:
            variant = queue.pop()
            executor.submit(variant.key, payload(study, variant))

    fill()
    show()
    while done < total:
        key, row, reason = executor.next_done()
        if row is None:
            reasons[key].append(reason)
            if len(reasons[key]) < ATTEMPTS:
                queue.append(by_key[key])  # next, on whichever worker is free
                fill()
                continue
            row = failed_row(by_key[key], reasons[key])
        results.add({**row, **(tags or {}).get(key, {})})
        done += 1
        planned += row.get('status') == PLANNED
        if on_row is not None:
            on_row(row)
        fill()  # before the count, so that "running" counts the workers busy again
        show()
    return total


def _clock(seconds: float) -> str:
    seconds = int(round(seconds))
    hours, rest = divmod(seconds, 3600)
    return f'{hours}:{rest // 60:02d}:{rest % 60:02d}'
