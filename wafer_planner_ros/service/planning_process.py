"""
Requests planned in a process of their own, so that planning never holds up a stop.

Planning a request is up to half a second of Python and numpy. In the node's own process it
holds the interpreter lock in stretches a stop request cannot cut short, and a crash in it
(a compiled kernel's, memory) would end the node. ``PlanningProcess`` plans them in a
child (``python -m wafer_planner_ros.service.planning_process``, a
``child_process.ChildProcess`` ``NICE`` steps below the node's priority, and stopped while
a stop is answered: ``giving_way.pausing``), over a pair of pipes: the thread that waits
for the answer waits on a pipe, the lock free, and a stop's answer has both cores.

``PlanningProcess.service(key, local)`` returns a ``ProcessService``: the service ``local``
(a ``service.planning.PlanningService``: the planner, its budget, its station tables) as
this process answers with it. A pair the station table holds is answered here at once, from
the table; anything else (``answer``, ``divert``) is planned in the child by the same
policy, the table's move lent for a port move (``PlanningService.lent_transfer``). The child
holds the planners of the two latest roadmaps it was handed, each under the caller's ``key``
(a roadmap and its cell, never two under one key): ``hold`` hands one over ahead
(``hold_ahead``: the node, as a roadmap serves), else it is handed over with the first
request that needs it, and again to a child started after one ended. The child answers what
its planner answers: proven and verified there (``Planner.plan``, ``Planner.divert``), its
``PlanningError`` raised here as it was raised there, and what its planner logs (warnings
and errors) logged here, as if said here. The child keeps the optima of its answers
(``Planner.optima``); those kept here (the station tables' curves) are handed to it with
the next exchange on that roadmap (those it lacks only, ``_taught``); it reads, verifies (a
few at a time: a request waits for no more) and stores the optima files
(``read_optima``, ``verify_optima``, ``store_optima``: ``optima_store``), so that neither
their verification nor their JSON holds this process's interpreter lock. A child that
fails or ends fails the one request under way (RuntimeError); the next starts another. One
that plans on ``STALLED_AFTER`` s past a request's deadline is ended.
"""

import itertools
import logging
import sys
import threading
import time
from typing import Callable, Optional

from wafer_planner_ros import giving_way
from wafer_planner_ros.cell.limits import LOADED, LOADS
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner import Planner, PlanResult
from wafer_planner_ros.roadmap.graph import import_for_searches
from wafer_planner_ros.service.child_process import ChildProcess, load_kernels, run_child
from wafer_planner_ros.service.optima_store import keep_verified, OptimaError, read_optima
from wafer_planner_ros.service.optima_store import save_optima
from wafer_planner_ros.service.planning import PlanningService, whole_curve

PACKAGE = 'wafer_planner_ros'
"""The logger whose warnings and errors (its modules') the child hands back."""
NICE = 10
"""How much lower the child's scheduling priority is than its parent's."""
HOLD_WAIT = 120.0
"""s a roadmap's hand-over is waited for at most (a first child loads its kernels)."""
STALLED_AFTER = 30.0
"""s after a request's deadline its child is ended, if it has not answered by then."""
CLOSE_WAIT = 0.05
"""s ``close`` waits for a plan under way to end before it kills the child."""
ROADMAPS = 2
"""Roadmaps the child holds (the oldest forgotten first): the serving one and the one
before, for requests received before it served."""


class PlanningProcess:
    """The child process planning requests, and the services that plan in it (the module)."""

    def __init__(self):
        """Start nothing yet: the child starts at the first hand-over or request."""
        self._child = ChildProcess('wafer_planner_ros.service.planning_process',
                                   'the planning process', HOLD_WAIT)
        giving_way.pausing(self._child)  # stopped while a stop is answered
        self._keys = itertools.count()

    @property
    def started(self) -> int:
        """Return how many children were started so far."""
        return self._child.started

    def start(self) -> None:
        """
        Start the child now, if it is not running (it imports while the caller goes on).

        Raise RuntimeError when it cannot be started.
        """
        self._child.exchange(lambda held: [])

    def key(self) -> int:
        """Return a new key, never given before, for a roadmap to hand over."""
        return next(self._keys)

    def hold(self, key: int, planner: Planner) -> None:
        """
        Hand the child ``planner``'s cell, roadmap and settings under ``key``, and wait.

        Raise RuntimeError when the child fails or ends (the first request that needs it
        hands it over again).
        """
        replies = self._child.exchange(lambda held: _held(held, key, planner))
        if replies and replies[-1][0] != 'held':
            _forget(self._child.held, key)  # not held: handed over again when needed
            raise RuntimeError(f'the planning process failed: {replies[-1][1]}')

    def hold_ahead(self, key: int, planner: Planner,
                   failed: Callable[[RuntimeError], None]) -> threading.Thread:
        """
        ``hold`` in a thread of its own, started at once and returned; ``failed(error)``.

        A request that needs the roadmap meanwhile waits for the hand-over (at most the
        child's start: a few tenths of a second), then is planned.
        """
        def hand_over() -> None:
            try:
                self.hold(key, planner)
            except RuntimeError as exc:
                failed(exc)
        thread = threading.Thread(target=hand_over, name='wafer_planner_hold', daemon=True)
        thread.start()
        return thread

    def service(self, key: int, local: PlanningService) -> 'ProcessService':
        """Return ``local`` as it answers with this process (``ProcessService``)."""
        return ProcessService(self, key, local)

    def plan(self, key: int, service: PlanningService, request: tuple,
             deadline: Optional[float]) -> PlanResult:
        """
        Return the child's answer to ``request`` as ``service`` gives it (``ProcessService``).

        Planned on the roadmap under ``key`` (``service``'s, handed over first if need be)
        with ``service``'s budget and sample period.
        """
        wait = None if deadline is None else deadline + STALLED_AFTER - time.monotonic()
        planner = service.planner
        head = ('plan', key, service.budget, planner.settings.sample_period)
        replies = self._child.exchange(
            lambda held: _held(held, key, planner) + _taught(held, key, planner)
            + [head + request], wait)
        for reply in replies[:-1]:
            if reply[0] != 'held':
                _forget(self._child.held, key)  # not held: handed over again next time
                raise RuntimeError(f'the planning process failed: {reply[1]}')
        reply = replies[-1]
        if reply[0] in ('planned', 'planning'):
            for name, level, message in reply[-1]:  # what the child's planner said, said here
                logging.getLogger(name).log(level, '%s', message)
        if reply[0] == 'planned':
            return reply[1]
        if reply[0] == 'planning':
            raise PlanningError(ErrorCode[reply[1]], reply[2])
        raise RuntimeError(f'the planning process failed: {reply[1]}')

    def read_optima(self, key: int, planner: Planner, cache_dir) -> list:
        """
        Have the child read the optima files of the roadmap under ``key`` (``optima_store``).

        Of every limit set; none verified yet (``verify_optima``), none used before. Return
        [(limit set, the file read or why none was, optima read)]. Raise RuntimeError when
        the child fails or ends.
        """
        return self._optima(key, planner, ('read_optima', key, str(cache_dir)))

    def verify_optima(self, key: int, planner: Planner, count: int) -> tuple:
        """
        Have the child verify ``count`` more of the optima it read, and keep those that pass.

        A few at a time, so that a request waits for no more than those (a few ms each).
        Return ([(limit set, kept, [why each other was not])], how many are left).
        """
        return self._optima(key, planner, ('verify_optima', key, count))

    def store_optima(self, key: int, planner: Planner, cache_dir,
                     turn: Optional[float] = None) -> Optional[list]:
        """
        Have the child store the optima it keeps of the roadmap under ``key``.

        Those of ``planner`` it lacks first. Return [(limit set, the file's path or why it
        was not stored)]; None when a plan under way has not ended within ``turn`` s.
        Raise RuntimeError when the child fails or ends.
        """
        return self._optima(key, planner, ('store_optima', key, str(cache_dir)), turn)

    def _optima(self, key: int, planner: Planner, message: tuple,
                turn: Optional[float] = None) -> Optional[list]:
        """Return the child's reply to an optima ``message`` on the roadmap under ``key``."""
        replies = self._child.exchange(lambda held: _held(held, key, planner)
                                       + _taught(held, key, planner) + [message], turn=turn)
        if replies is None:
            return None
        if replies[-1][0] != 'optima':
            _forget(self._child.held, key)
            raise RuntimeError(f'the planning process failed: {replies[-1][1]}')
        return replies[-1][1]

    def close(self) -> None:
        """End the child at once (nothing waits for a plan any more)."""
        self._child.close(wait=CLOSE_WAIT, grace=0.0)


def _held(held: set, key: int, planner: Planner) -> list:
    """Return the hand-over of ``planner`` under ``key`` unless the child holds it."""
    if key in held:
        return []
    held.add(key)
    return [('hold', key, planner.cell, planner.roadmap, planner.settings)]


def _taught(held: set, key: int, planner: Planner) -> list:
    """
    Return the hand-over of the optima of ``planner`` the child under ``key`` lacks.

    One message per limit set with optima kept since those last handed over (``held``
    records the last serial handed over, and is emptied when another child starts).
    """
    messages = []
    for load, optima in planner.libraries.items():
        sent = next((serial for entry, serial in _sent(held, key, load)), 0)
        new = optima.since(sent)
        if new:
            held.difference_update(_sent(held, key, load))
            held.add((('optima', key, load), max(optimum.serial for optimum in new)))
            messages.append(('optima', key, load, new))
    return messages


def _forget(held: set, key: int) -> None:
    """Record that the child does not hold the roadmap under ``key``, nor its optima."""
    held.discard(key)
    held.difference_update([entry for entry in held if isinstance(entry, tuple)
                            and entry[0][:2] == ('optima', key)])


def _sent(held: set, key: int, load: str) -> list:
    """Return the record of the optima of ``load`` handed over under ``key``, if any."""
    return [entry for entry in held if isinstance(entry, tuple)
            and entry[0] == ('optima', key, load)]


class ProcessService:
    """A ``PlanningService`` whose plans are made in a ``PlanningProcess`` (the module)."""

    def __init__(self, process: PlanningProcess, key: int, local: PlanningService):
        """Answer as ``local`` does, planning in ``process`` on the roadmap under ``key``."""
        self.process, self.key, self.local = process, key, local

    @property
    def planner(self) -> Planner:
        """Return the local service's: the child's is a copy."""
        return self.local.planner

    def holds(self, start, goal, load: str = LOADED) -> bool:
        """Return whether the station table answers ``start`` to ``goal`` (at once, here)."""
        return self.local.holds(start, goal, load)

    def answer(self, start, goal, deadline: Optional[float] = None,
               load: str = LOADED) -> PlanResult:
        """Return the answer ``PlanningService.answer`` gives: a held pair here, else planned."""
        if self.local.holds(start, goal, load):
            return self.local.answer(start, goal, deadline, load)
        transfer = None if self.local.budget is None else \
            self.local.lent_transfer(start, goal, load)
        return self.process.plan(self.key, self.local, (
            'answer', start, goal, deadline, load, transfer), deadline)

    def divert(self, trajectory, at: float, goal, label: str,
               deadline: Optional[float] = None, load: str = LOADED,
               leaves: Optional[float] = None) -> PlanResult:
        """Return the divert ``PlanningService.divert`` gives, planned in the child."""
        return self.process.plan(self.key, self.local, (
            'divert', trajectory, at, goal, label, deadline, load, leaves), deadline)


class _Planning:
    """The child's side: the planners it holds, and the requests it plans on them."""

    def __init__(self):
        self.planners = {}
        """key -> the planner of a roadmap handed over, the latest ``ROADMAPS``."""
        self.unverified = {}
        """key -> the optima read from its files not yet verified (``verify_optima``)."""
        self.loaded = False
        self.said = _Said()
        logging.getLogger(PACKAGE).addHandler(self.said)

    def reply(self, message: tuple) -> tuple:
        """Hold a roadmap (``('hold', key, ...)``) or plan a request on one (``'plan'``)."""
        if message[0] == 'hold':
            _, key, cell, roadmap, settings = message
            if not self.loaded:  # only now: the node has loaded or compiled them first
                load_kernels()
                self.loaded = True
            self.planners[key] = Planner(cell, roadmap, settings)
            for built in ('graph', 'components', 'tree'):
                getattr(roadmap, built)  # what the first search builds: built now
            for old in sorted(self.planners)[:-ROADMAPS]:
                del self.planners[old]
                self.unverified.pop(old, None)
            return ('held', key)
        if message[0] == 'optima':  # optima the parent kept: drafts here too
            _, key, load, optima = message
            kept = self.planners[key].for_load(load).optima
            for optimum in optima:
                kept.add(optimum.start, optimum.goal, optimum.curve)
            return ('held', key)
        if message[0] == 'read_optima':
            _, key, cache_dir = message
            read, self.unverified[key] = _read(self.planners[key], cache_dir)
            return ('optima', read)
        if message[0] == 'verify_optima':
            _, key, count = message
            unverified = self.unverified.get(key, [])
            taken, self.unverified[key] = unverified[:count], unverified[count:]
            return ('optima', (_verified(self.planners[key], taken),
                               len(self.unverified[key])))
        if message[0] == 'store_optima':
            _, key, cache_dir = message
            return ('optima', _stored(self.planners[key], cache_dir))
        _, key, budget, sample_period, kind, *arguments = message
        service = PlanningService(self.planners[key]).using(budget, sample_period)
        self.said.records = []
        try:
            plan = service.answer if kind == 'answer' else service.divert
            return ('planned', plan(*arguments), self.said.records)
        except PlanningError as exc:
            return ('planning', exc.code.name, exc.message, self.said.records)


def _read(planner: Planner, cache_dir) -> tuple:
    """
    Return what reading every limit set's optima file found, and the optima to verify.

    ([(limit set, path or why none, count)], [(limit set, place in its file, as stored)]).
    """
    read, unverified = [], []
    for load in LOADS:
        try:
            path, optima = read_optima(whole_curve(planner).for_load(load), cache_dir)
        except OptimaError as exc:
            read.append((load, str(exc), 0))
            continue
        read.append((load, path, len(optima)))
        unverified += [(load, k, stored) for k, stored in enumerate(optima)]
    return read, unverified


def _verified(planner: Planner, taken: list) -> list:
    """Return [(limit set, kept, [why not])] of verifying and keeping ``taken`` optima."""
    done = []
    for load in dict.fromkeys(load for load, _, _ in taken):
        kept, rejected = keep_verified(whole_curve(planner).for_load(load), [
            (k, stored) for of, k, stored in taken if of == load])
        done.append((load, kept, rejected))
    return done


def _stored(planner: Planner, cache_dir) -> list:
    """Return [(limit set, path or why not)] of storing every limit set's optima kept."""
    stored = []
    for load, optima in planner.libraries.items():
        if len(optima):
            try:
                stored.append((load, save_optima(whole_curve(planner).for_load(load),
                                                 cache_dir)))
            except OSError as exc:
                stored.append((load, str(exc)))
    return stored


class _Said(logging.Handler):
    """The child's warnings and errors while it plans, handed back with the answer."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.records = []

    def emit(self, record: logging.LogRecord) -> None:
        """Keep (logger name, level, message) of ``record``."""
        self.records.append((record.name, record.levelno, record.getMessage()))


def main(argv=None) -> int:
    """Run the child: ``python -m wafer_planner_ros.service.planning_process IN_FD OUT_FD``."""
    return run_child(argv, _Planning().reply, idle=False, nice=NICE, prepare=import_for_searches)


if __name__ == '__main__':
    sys.exit(main())
