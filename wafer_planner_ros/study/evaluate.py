"""
One variant, from its cell to its row of results.

The cell is validated like any cell file (an invalid one is a row with the reason), its
roadmap built, every station pair planned loaded (the retracted poses: the moves the
station table holds) and the swap cycle of every loadport/loadlock pair with ports
(``service.cycle``: port to port, loaded out, empty back). Every motion is the planner's
verified answer.

The row's figures are a function of the variant and the study's settings alone, so a
variant gives the same row on any worker; ``cost`` (seconds and where) is the one part
that differs from run to run.
"""

import logging
import os
import socket
import time

import numpy as np

from wafer_planner_ros import __version__
from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.errors import CellError, PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.builder import build_roadmap
from wafer_planner_ros.roadmap.graph import RoadmapSettings
from wafer_planner_ros.service.cycle import loadport_loadlock_pairs, SECONDS_PER_HOUR
from wafer_planner_ros.service.cycle import swap_cycle
from wafer_planner_ros.study.parameters import footprint

INVALID, PLANNED, INCOMPLETE, FAILED = 'invalid', 'planned', 'incomplete', 'failed'
"""A row's status: the cell is invalid; every move planned; some move could not be;
evaluating it failed twice (the worker died or raised)."""


def task(payload: dict) -> dict:
    """
    Evaluate one variant sent to a worker; return its row.

    ``payload``: the variant (``key``, ``index``, ``values``, ``document``) and the study's
    settings (``nodes``, ``seed``, ``method``, ``version``). A worker with another version
    of the package refuses (its rows would not be the study's). The planner's warnings
    (a branch combination that failed verification, and the next tried) are not shown: the
    row holds what failed.
    """
    logging.getLogger('wafer_planner_ros').setLevel(logging.ERROR)
    if payload['version'] != __version__:
        raise RuntimeError(f'the worker runs wafer_planner_ros {__version__}, the study '
                           f"{payload['version']}")
    return evaluate(payload['key'], payload['index'], payload['values'], payload['document'],
                    payload['nodes'], payload['seed'], payload['method'])


def evaluate(key: str, index: int, values: dict, document: dict, nodes: int, seed: int,
             method: str) -> dict:
    """Return the row of one variant (never raises for a bad cell or a failed move)."""
    started = time.perf_counter()
    row = {'variant': key, 'index': index, 'parameters': dict(values), 'status': INVALID,
           'reason': '', 'footprint': None}
    try:
        row['footprint'] = footprint(document)
        cell = Cell.from_dict(document, source=f'variant {key}')
    except (CellError, ValueError, TypeError, KeyError) as exc:
        row['reason'] = str(exc) or type(exc).__name__
        row['cost'] = _cost(started, 0.0)
        return row
    row['cell_digest'] = cell.digest
    begun = time.perf_counter()
    roadmap = build_roadmap(cell, RoadmapSettings(nodes=nodes), seed)
    built = time.perf_counter() - begun
    row['roadmap'] = {'nodes': roadmap.node_count, 'edges': roadmap.edge_count,
                      'hash': roadmap.digest}
    planner = Planner(cell, roadmap, PlannerSettings(method=method))
    results, failures, pairs = [], [], []
    for start, goal in station_pairs(cell):
        try:
            result = planner.plan(start, goal)
        except PlanningError as exc:
            failures.append({'from': start, 'to': goal, 'load': 'loaded',
                             'code': exc.code.value, 'message': exc.message})
            pairs.append({'from': start, 'to': goal, 'cycle_time': None,
                          'code': exc.code.value})
            continue
        results.append(result)
        pairs.append({'from': start, 'to': goal, 'cycle_time': result.cycle_time,
                      'code': ''})
    swaps = []
    for loadport, loadlock in loadport_loadlock_pairs(cell):
        cycle = swap_cycle(planner, loadport, loadlock)
        for move in cycle.moves + cycle.stop_and_go_moves:
            if move.result is not None:
                results.append(move.result)
        for move in cycle.moves:
            if move.result is None:
                code, _, message = move.error.partition(': ')
                failures.append({'from': move.start, 'to': move.goal, 'load': move.load,
                                 'code': code, 'message': message})
        if len(cycle.moves) < 2:  # the way back was not tried
            failures.append({'from': f'{loadlock}:inside', 'to': f'{loadport}:inside',
                             'load': 'empty', 'code': 'NOT_TRIED',
                             'message': 'the way out failed'})
        swaps.append({'loadport': loadport, 'loadlock': loadlock, 'cycle': cycle.cycle,
                      'stop_and_go': cycle.stop_and_go, 'gain': cycle.gain})
    cycles = [s['cycle'] for s in swaps]
    complete = bool(swaps) and all(c is not None for c in cycles) and not failures
    swap = float(np.mean(cycles)) if complete else None
    row.update({
        'status': PLANNED if complete else INCOMPLETE,
        'reason': '' if complete else (
            'the cell has no loadport and loadlock with a port' if not swaps else
            f'{len(failures)} moves could not be planned'),
        'swap_cycle': swap,
        'wafers_per_hour': None if swap is None else SECONDS_PER_HOUR / swap,
        'best_swap_cycle': min((c for c in cycles if c is not None), default=None),
        'swaps': swaps, 'pairs': pairs,
        'min_clearance': min((r.min_clearance for r in results), default=None),
        'peak_jerk': np.max([r.verification.peak_jerk for r in results], axis=0).tolist()
        if results else None,
        'failures': failures,
        'cost': _cost(started, built),
    })
    return row


def _cost(started: float, roadmap: float) -> dict:
    """Return what a variant cost, and where: the one part of a row that varies by run."""
    return {'seconds': time.perf_counter() - started, 'roadmap_seconds': roadmap,
            'worker': f'{socket.gethostname()}:{os.getpid()}'}
