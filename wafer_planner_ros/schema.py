"""Typed, path-aware readers for the cell YAML; every failure names its key path."""

import math

import numpy as np

from wafer_planner_ros.errors import CellError


def mapping(value, path: str, required=(), optional=()) -> dict:
    """Return ``value`` as a dict after checking its keys against the allowed ones."""
    if not isinstance(value, dict):
        raise CellError(path, f'must be a mapping, got {type(value).__name__}')
    allowed = tuple(required) + tuple(optional)
    for key in value:
        if key not in allowed:
            raise CellError(join(path, key),
                            f'unknown key (expected one of: {", ".join(allowed)})')
    for key in required:
        if key not in value:
            raise CellError(join(path, key), 'missing')
    return value


def number(value, path: str, positive=False) -> float:
    """Return a finite float (and > 0 when ``positive``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CellError(path, f'must be a number, got {value!r}')
    if not math.isfinite(value):
        raise CellError(path, f'must be finite, got {value!r}')
    if positive and value <= 0:
        raise CellError(path, f'must be > 0, got {value!r}')
    return float(value)


def vector(value, path: str, length: int, positive=False) -> np.ndarray:
    """Return a list of ``length`` numbers as a float array."""
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise CellError(path, f'must be a list of {length} numbers, got {value!r}')
    return np.array([number(v, f'{path}[{i}]', positive) for i, v in enumerate(value)])


def text(value, path: str) -> str:
    """Return a non-empty string."""
    if not isinstance(value, str) or not value.strip():
        raise CellError(path, f'must be a non-empty string, got {value!r}')
    return value


def points(value, path: str, minimum: int) -> np.ndarray:
    """Return a list of at least ``minimum`` [x, y] points as an (N, 2) array."""
    if not isinstance(value, (list, tuple)) or len(value) < minimum:
        raise CellError(path, f'must be a list of at least {minimum} [x, y] points')
    return np.array([vector(p, f'{path}[{i}]', 2) for i, p in enumerate(value)])


def join(path: str, key) -> str:
    """Return the key path of ``key`` below ``path``."""
    return f'{path}.{key}' if path else str(key)
