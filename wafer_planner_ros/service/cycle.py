"""
The cycle a fab buys: a single-blade swap between a loadport and a loadlock.

Per wafer the blade makes two moves, port to port: ``<loadport>:inside`` ->
``<loadlock>:inside`` loaded (the wafer from its FOUP into the loadlock), then
``<loadlock>:inside`` -> ``<loadport>:inside`` empty (back for the next wafer). Each is one
move (``Planner.plan``): non-stop, unless stopping at the port mouths is faster (its
``stops``); the way back is planned on the elbow branches the way out
ended and started on, so that the cycle repeats. When the way out backwards is faster than
the way back as planned and passes the empty set's verification, it is the way back
(``adoption.faster``; the optimiser is local, and the empty set allows all the loaded one
does).

It is compared with the same cycle as a controller without non-stop moves or an empty
limit set makes it: each way the move that stops at both port mouths
(``Planner.stop_and_go``: straight out of the port to rest at its mouth, the transfer from
rest to rest, straight in), loaded; the way out on its fastest elbow branches, the way back
on those it ended and started on (or the way out backwards, when that is faster: a stop
reversed in time keeps every limit a stop does).

Both are reported in seconds of motion per wafer, with wafers per hour of motion
(3600 / seconds: the robot's motion alone, without the stations' own times) and the gain
(stop-and-go / cycle: how many more wafers an hour).
"""

from dataclasses import dataclass, replace
from typing import Callable, Optional, Tuple

from wafer_planner_ros.cell.limits import EMPTY, LOADED
from wafer_planner_ros.cell.stations import INSIDE
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner import Planner, PlanResult
from wafer_planner_ros.service.adoption import faster

SECONDS_PER_HOUR = 3600.0


@dataclass(frozen=True, eq=False)
class Move:
    """One move of a cycle: its ends, limit set and elbow branches, and how it went."""

    start: str
    goal: str
    load: str
    branches: Tuple[Optional[int], Optional[int]]
    """The elbow branches it was planned on (None: any)."""
    result: Optional[PlanResult] = None
    error: str = ''
    """The code and the sentence when it could not be planned."""

    @property
    def cycle_time(self) -> Optional[float]:
        """Return its duration (s), None when it failed."""
        return None if self.result is None else self.result.cycle_time

    def row(self) -> dict:
        """Return the move as JSON data (``stops``: where it stops on its way, ``Planner``)."""
        return {'from': self.start, 'to': self.goal, 'load': self.load,
                'branches': list(self.result.branches if self.result else self.branches),
                'cycle_time': self.cycle_time, 'error': self.error,
                'adopted': bool(self.result and self.result.metrics.get('adopted')),
                'stops': self.result.metrics.get('stops', 0) if self.result else None}


@dataclass(frozen=True, eq=False)
class SwapCycle:
    """The swap cycle of one loadport/loadlock pair, and its stop-and-go counterpart."""

    loadport: str
    loadlock: str
    moves: Tuple[Move, ...]
    """Non-stop: loaded out, empty back (the way back absent when the way out failed)."""
    stop_and_go_moves: Tuple[Move, ...]
    """Stopping at the mouths: out and back (empty when either could not be planned)."""
    stop_and_go_errors: Tuple[str, ...] = ()
    """Why the move that failed did (its ends, then its error)."""

    @property
    def cycle(self) -> Optional[float]:
        """Return the non-stop cycle's seconds of motion per wafer (None: a move failed)."""
        return _total(self.moves, 2)

    @property
    def stop_and_go(self) -> Optional[float]:
        """Return the stop-and-go cycle's seconds of motion per wafer (None: none planned)."""
        return _total(self.stop_and_go_moves, 2)

    @property
    def gain(self) -> Optional[float]:
        """Return stop-and-go / non-stop: wafers per hour of motion, non-stop over stop-and-go."""
        if self.cycle is None or self.stop_and_go is None:
            return None
        return self.stop_and_go / self.cycle

    def row(self) -> dict:
        """Return the cycle as JSON data (``wafer-plan --cycle --json``)."""
        return {'loadport': self.loadport, 'loadlock': self.loadlock,
                'cycle': self.cycle, 'wafers_per_hour': _per_hour(self.cycle),
                'stop_and_go': self.stop_and_go,
                'stop_and_go_wafers_per_hour': _per_hour(self.stop_and_go),
                'gain': self.gain, 'moves': [m.row() for m in self.moves],
                'stop_and_go_moves': [m.row() for m in self.stop_and_go_moves],
                'stop_and_go_errors': list(self.stop_and_go_errors)}


def swap_cycle(planner: Planner, loadport: str, loadlock: str,
               plan: Optional[Callable[..., PlanResult]] = None) -> SwapCycle:
    """
    Return the swap cycle of ``loadport`` and ``loadlock`` (both need a port).

    ``plan(start, goal, branches, load)``: how each non-stop move is planned (default:
    ``planner``; the stop-and-go ones are ``Planner.stop_and_go``'s);
    raises PlanningError when it cannot be.
    """
    plan = plan or (lambda start, goal, branches, load: planner.plan(
        start, goal, branches=branches, load=load))
    lp, ll = f'{loadport}{INSIDE}', f'{loadlock}{INSIDE}'
    out = _move(plan, lp, ll, LOADED, (None, None))
    moves = (out,)
    if out.result is not None:
        start, goal = out.result.branches
        moves += (_faster(planner, _move(plan, ll, lp, EMPTY, (goal, start)), out),)

    def stop(start, goal, branches, load):
        return planner.stop_and_go(start, goal, load=load, branches=branches)

    chain = [_move(stop, lp, ll, LOADED, (None, None))]
    if chain[0].result is not None:
        start, goal = chain[0].result.branches
        chain.append(_faster(planner, _move(stop, ll, lp, LOADED, (goal, start)), chain[0]))
    errors = tuple(f'{m.start} -> {m.goal}: {m.error}' for m in chain if m.result is None)
    return SwapCycle(loadport, loadlock, moves, () if errors else tuple(chain), errors)


def loadport_loadlock_pairs(cell) -> list:
    """Return every (loadport, loadlock) pair of stations with a port (by role), by name."""
    names = sorted(name for name, station in cell.stations.items() if station.port)
    role = {name: cell.stations[name].role for name in names}
    return [(a, b) for a in names for b in names
            if role[a] == 'loadport' and role[b] == 'loadlock']


def _faster(planner: Planner, back: Move, out: Move) -> Move:
    """Return the way back, or the way out backwards if faster and it verifies for it."""
    result = faster(planner.for_load(back.load), back.result, out.result, backwards=True)
    return back if result is back.result else replace(back, result=result, error='')


def _move(plan, start: str, goal: str, load: str, branches) -> Move:
    try:
        result = plan(start, goal, None if branches == (None, None) else branches, load)
    except PlanningError as exc:
        return Move(start, goal, load, branches, error=f'{exc.code.value}: {exc.message}')
    return Move(start, goal, load, branches, result)


def _total(moves, count: int) -> Optional[float]:
    times = [m.cycle_time for m in moves]
    if len(times) != count or any(t is None for t in times):
        return None
    return float(sum(times))


def _per_hour(seconds: Optional[float]) -> Optional[float]:
    return None if seconds is None else SECONDS_PER_HOUR / seconds
