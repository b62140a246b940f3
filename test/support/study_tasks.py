"""Stand-in tasks for the study's executors: cheap rows, a worker that dies, one that raises."""

import os
from pathlib import Path


def row_of(payload: dict) -> dict:
    """Return a row made from the payload alone."""
    return {'variant': payload['key'], 'index': payload['index'], 'status': 'planned',
            'parameters': payload['values'], 'swap_cycle': float(payload['index'])}


def flaky(payload: dict) -> dict:
    """Die on the first attempt of a variant whose key starts with 'die', raise on 'bad'."""
    key = payload['key']
    if key.startswith('bad'):
        raise ValueError(f'{key} cannot be evaluated')
    mark = Path(payload['marks']) / key
    if key.startswith('die') and not mark.exists():
        mark.touch()
        os._exit(3)
    return row_of(payload)
