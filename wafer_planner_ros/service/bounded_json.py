"""
Reading JSON from anyone, boundedly: numbers no float holds marked, keys given twice noted.

A request's text comes from any sender: ``loads`` reads it with every number checked to be
one a float holds (``NotFinite`` otherwise, as written or by its length, never an
overflow or a refused conversion later) and every object a ``JsonObject`` that lists the
keys it had more than once; ``quote`` quotes any value in an error message in a bounded
number of characters, however large or deep it is, and never fails.
"""

import json
import math

QUOTE = 200
"""Most characters of a request's value that an error message quotes."""


def loads(text: str):
    """Return the JSON value of ``text`` read as the module says (raise as ``json.loads``)."""
    return json.loads(text, parse_int=parse_integer, parse_float=parse_float,
                      parse_constant=NotFinite, object_pairs_hook=JsonObject)


def quote(value, limit: int = QUOTE) -> str:
    """Return ``value`` as JSON text of at most about ``limit`` characters; never raise."""
    parts = []
    room = [limit]

    def put(text: str) -> None:
        parts.append(text)
        room[0] -= len(text)
        if room[0] < 0:
            raise Full

    def walk(item, depth: int) -> None:
        if depth > 8:  # deep nesting: bounded work, and no RecursionError
            put('...')
        elif isinstance(item, NotFinite):
            put(item.quoted)
        elif isinstance(item, str):
            put(json.dumps(item[:limit]))  # ASCII escapes: lone surrogates too
        elif isinstance(item, bool) or item is None:
            put(json.dumps(item))
        elif isinstance(item, int):
            put(str(item) if item.bit_length() < 1024 else f'({digits(item)} digits)')
        elif isinstance(item, float):
            put(json.dumps(item))
        elif isinstance(item, dict):
            put('{')
            for index, (key, element) in enumerate(item.items()):
                put(', ' if index else '')
                walk(key, depth + 1)
                put(': ')
                walk(element, depth + 1)
            put('}')
        elif isinstance(item, (list, tuple)):
            put('[')
            for index, element in enumerate(item):
                put(', ' if index else '')
                walk(element, depth + 1)
            put(']')
        else:
            put(f'<{type(item).__name__}>')

    try:
        walk(value, 0)
    except Full:
        return ''.join(parts)[:limit] + '...'
    except Exception:  # noqa: B902 - a quote in an error message must not fail itself
        return f'<{type(value).__name__}>'
    return ''.join(parts)


class Full(Exception):
    """A quote has reached its length."""


class NotFinite:
    """A JSON number that no finite float holds: as written, or its length (``quoted``)."""

    __slots__ = ('text', 'quoted')

    def __init__(self, text: str, literal: bool = True):
        self.text = text
        self.quoted = text if literal else f'({text})'


class JsonObject(dict):
    """A JSON object; ``repeated`` lists the keys it has more than once."""

    def __init__(self, pairs):
        super().__init__(pairs)
        self.repeated = []
        if len(self) != len(pairs):
            seen = set()
            self.repeated = [k for k, _ in pairs if k in seen or seen.add(k)]


def parse_integer(text: str):
    """Return a JSON integer, or ``NotFinite`` for one no float holds."""
    digits = len(text) - text.startswith('-')
    if digits > 309:  # at least 10**309: beyond the largest float, and int() may refuse it
        return NotFinite(f'{digits} digits', literal=False)
    value = int(text)
    try:
        float(value)
    except OverflowError:
        return NotFinite(f'{digits} digits', literal=False)
    return value


def parse_float(text: str):
    """Return a JSON number, or ``NotFinite`` for one that is not finite."""
    value = float(text)
    if math.isfinite(value):
        return value
    if len(text) <= 40:
        return NotFinite(text)
    return NotFinite(f'{len(text)} characters', literal=False)


def digits(value: int) -> int:
    """Return how many decimal digits an integer has (from its bit length, cheaply)."""
    return int(abs(value).bit_length() * math.log10(2)) + 1
