"""Typed, path-aware readers for the cell YAML; every failure names its key path."""

import math
import reprlib

import numpy as np

from wafer_planner_ros.errors import CellError

BRIEF = 200
"""Longest quotation of a value in a message (characters)."""
MAX_TEXT = 200
"""Longest name ``text()`` accepts (characters)."""
MAX_COORDINATE = 1000.0
"""m: the largest |x| or |y| of a polygon vertex or the base (an EFEM is a few metres)."""
MAX_JOINT_ANGLE = 100.0
"""rad: the largest |position limit| or heading (about 16 turns)."""

# Bounded at every level: a value can be an alias-expanded structure of 10**5 nodes, or a
# string of megabytes, and its full repr would be built before any slicing of it.
_REPR = reprlib.Repr()
_REPR.maxlevel = 3
_REPR.maxtuple = _REPR.maxlist = _REPR.maxset = _REPR.maxfrozenset = _REPR.maxdeque = 8
_REPR.maxdict = 4
_REPR.maxstring = _REPR.maxother = BRIEF
_REPR.maxlong = 40


def brief(value, limit: int = BRIEF) -> str:
    """Return the repr of ``value`` for a message: at most ``limit`` characters."""
    try:
        quoted = _REPR.repr(value)
    except Exception:  # noqa: B902 - a message must never fail, and a repr may
        quoted = f'<{type(value).__name__}>'
    if len(quoted) > limit:
        quoted = quoted[:limit - 3] + '...'
    return quoted


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
        raise CellError(path, f'must be a number, got {brief(value)}')
    try:
        result = float(value)
    except OverflowError:
        raise CellError(path, f'{_digits(value)} does not fit a float') from None
    if not math.isfinite(result):
        raise CellError(path, f'must be finite, got {brief(value)}')
    if positive and result <= 0:
        raise CellError(path, f'must be > 0, got {brief(value)}')
    return result


def vector(value, path: str, length: int, positive=False) -> np.ndarray:
    """Return a list of ``length`` numbers as a float array."""
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise CellError(path, f'must be a list of {length} numbers, got {brief(value)}')
    return np.array([number(v, f'{path}[{i}]', positive) for i, v in enumerate(value)])


def text(value, path: str) -> str:
    """Return a non-empty string of at most ``MAX_TEXT`` characters."""
    if not isinstance(value, str) or not value.strip():
        raise CellError(path, f'must be a non-empty string, got {brief(value)}')
    if len(value) > MAX_TEXT:
        raise CellError(path, f'must be at most {MAX_TEXT} characters, got {len(value):,} '
                              f'({brief(value, 60)})')
    return value


def points(value, path: str, minimum: int) -> np.ndarray:
    """Return a list of at least ``minimum`` [x, y] points as an (N, 2) array."""
    if not isinstance(value, (list, tuple)) or len(value) < minimum:
        raise CellError(path, f'must be a list of at least {minimum} [x, y] points')
    return np.array([vector(p, f'{path}[{i}]', 2) for i, p in enumerate(value)])


def join(path: str, key) -> str:
    """Return the key path of ``key`` below ``path`` (a long key shortened, for messages)."""
    key = str(key)
    if len(key) > BRIEF:
        key = f'{key[:BRIEF // 2]}...{key[-20:]}'
    return f'{path}.{key}' if path else key


def _digits(value: int) -> str:
    """Return a huge integer as its first and last digits and its length."""
    sign = '-' if value < 0 else ''
    try:
        digits = str(abs(value))
    except ValueError:  # beyond sys.get_int_max_str_digits(): only the length is cheap
        return f'{sign}an integer of about {int(abs(value).bit_length() * math.log10(2)):,} ' \
               f'digits'
    return f'{sign}{digits[:5]}...{digits[-4:]} ({len(digits):,} digits)'


def coordinates(values, path: str, beyond: str = 'farther out than'):
    """
    Return ``values`` (m); refuse one beyond MAX_COORDINATE, too large to be part of a cell.

    Beyond it the geometry's arithmetic would overflow long before it meant anything.
    """
    values = np.asarray(values, float)
    far = np.argwhere(np.abs(values) > MAX_COORDINATE)
    if len(far):
        where = ''.join(f'[{int(k)}]' for k in far[0])  # nothing for a single number
        raise CellError(f'{path}{where}', f'{values[tuple(far[0])]:.6g} m is {beyond} '
                                          f'{MAX_COORDINATE:g} m: not a plausible cell')
    return values
