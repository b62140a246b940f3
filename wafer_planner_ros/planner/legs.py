"""
What a planner keeps between requests: transfers between port mouths and a port's ways.

A move through a port is its ways through the ports and a transfer between the port mouths.
The transfer between two mouths on their elbow branches serves every move through those
ports, so the last ``LEGS_KEPT`` verified answers planned without a budget are kept by their
ends (a station pair's answer is such a transfer), with the other elbow-branch combinations
such an answer finished but did not verify (drafts, verified when first asked for). Each
way through a port is kept too: its bounds (or why it has none) and its free end. Every kind
is bounded, the oldest out first; all of it is safe to share between threads.
"""

import threading
from typing import Callable, Hashable

import numpy as np

LEGS_KEPT = 64
"""Of each kind, the most a planner keeps: every retract and extend of 16 stations with
ports on both elbow branches, with 32 transfers between them."""
KINDS = ('legs', 'drafts', 'ends', 'bounds')
"""Verified transfers; finished, unverified combinations; free ends; a way's bounds."""


def leg_key(qa: np.ndarray, qb: np.ndarray, branches) -> tuple:
    """Return the key of a move between two configurations on their branches."""
    return tuple((branch, q.tobytes()) for branch, q in zip(branches, (qa, qb)))


class Legs:
    """A planner's kept transfers, drafts and ways through ports, each kind bounded."""

    def __init__(self, size: int = LEGS_KEPT):
        """Keep at most ``size`` of each kind."""
        self._size = size
        self._kept = {kind: {} for kind in KINDS}
        self._lock = threading.Lock()

    def leg_or_draft(self, key: Hashable) -> tuple:
        """Return (the kept transfer, None) or (None, the draft taken out, or None)."""
        with self._lock:
            leg = self._kept['legs'].get(key)
            return leg, None if leg is not None else self._kept['drafts'].pop(key, None)

    def holds(self, kind: str, key: Hashable) -> bool:
        """Return whether ``key`` is kept of ``kind``."""
        with self._lock:
            return key in self._kept[kind]

    def cached(self, kind: str, key: Hashable, make: Callable[[], object]):
        """Return the kept value of ``kind`` at ``key``, else ``make()`` kept (made unlocked)."""
        with self._lock:
            found = self._kept[kind].get(key)
        if found is None:
            found = make()
            self.keep(kind, key, found)
        return found

    def keep(self, kind: str, key: Hashable, value) -> None:
        """Keep ``value`` of ``kind`` at ``key``, the oldest out beyond the bound."""
        with self._lock:
            kept = self._kept[kind]
            if key not in kept and len(kept) >= self._size:
                del kept[next(iter(kept))]
            kept[key] = value
