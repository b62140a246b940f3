"""
How a request is answered: one policy for the node, ``wafer-plan`` and ``wafer-replay``.

``PlanningService(planner, table, budget).answer(start, goal, deadline)``, where the station
tables are the service's cache (``tables``, one per limit set: ``table`` is the loaded one;
the node sets them as they are planned; ``holds`` says whether they answer a request at
once):

- a pair the station table of its limit set holds (retracted to retracted, or inside a port
  to inside another): from the table (every entry verified in full when it was loaded or
  planned; ``service.table``);
- without a budget (``budget`` None: ``wafer-plan``, a replay): planned by ``planner`` with
  its own curve method, as long as it takes (until ``deadline``, if any);
- with a budget (the node: ``planning.optimise_budget`` s): anything else (joint angles, a
  station pair the table does not hold, or not yet: it is being planned) gets the
  whole-curve optimisation for at most the budget, and never more than half of what is left
  before ``deadline``, so that the verification and the answer keep their time; the best
  proven curve by then. When it has proven none by then (some joint requests; how many:
  doc/benchmark.md), the coarse stage runs on to its first proven curve, close to the
  optimum, up to half-way to ``deadline``; only if it proves none by then is the answer
  the corridor curve (timed until it converges or half-way to what is left), far slower
  than the optimum. A budget below ``MIN_BUDGET`` (or 0) gives
  the corridor curve, which takes milliseconds.

``divert`` answers a move left in motion (``Planner.divert``) by the same policy: the move
from where its controlled stop rests is planned as a request for joint angles is; with the
whole-curve optimisation (within a budget, or a planner of that method) one curve from
the moving state is then sought too, for up to ``stop.BLEND_SECONDS`` more.

A budgeted answer names its budget (``metrics['budget']``). Its cycle time depends on how
fast the machine was, so a replay cannot reproduce it: ``within_budget`` tells such answers
from the record of a query.
"""

from dataclasses import replace
import time
from typing import Dict, Mapping, Optional, Type

from wafer_planner_ros.cell.limits import LOADED
from wafer_planner_ros.cell.stations import INSIDE, station_name
from wafer_planner_ros.planner import Planner, PlanResult
from wafer_planner_ros.service.table import StationTable
from wafer_planner_ros.trajectory.methods import CurveMethod, KnotTiming, WholeCurve

MIN_BUDGET = 0.05
"""s: a budget below this (the request's deadline is near) gets the corridor curve
(``KnotTiming``: milliseconds) instead of the whole-curve optimisation (``WholeCurve``, the
station table's method)."""


class PlanningService:
    """A planner, its station table as a cache, and how a request is answered (the module)."""

    def __init__(self, planner: Planner, table: Optional[StationTable] = None,
                 budget: Optional[float] = None,
                 tables: Optional[Dict[str, StationTable]] = None):
        """
        Answer with ``planner`` and its station tables; ``budget`` s of optimisation, or None.

        ``tables``: by limit set (``StationTable.load``); ``table``: the loaded one.
        """
        self.planner, self.budget = planner, budget
        self.tables: Dict[str, StationTable] = dict(tables or {})
        """The station tables by limit set (none for a set: none, or not yet planned); one
        may be set at any time (the node sets each as it is planned), never mutated."""
        if table is not None:
            self.table = table

    @property
    def table(self) -> Optional[StationTable]:
        """Get the loaded moves' station table: None when there is none, or not yet."""
        return self.tables.get(LOADED)

    @table.setter
    def table(self, table: Optional[StationTable]) -> None:
        self.set_table(LOADED, table)

    def set_table(self, load: str, table: Optional[StationTable]) -> None:
        """Answer from ``table`` the moves of the limit set ``load`` (None: from none)."""
        tables = dict(self.tables)  # replaced whole: a reader sees the old or the new
        if table is None:
            tables.pop(load, None)
        else:
            tables[load] = table
        self.tables = tables

    def holds(self, start, goal, load: str = LOADED) -> bool:
        """Return whether the station table answers ``start`` to ``goal`` (at once)."""
        return self._holding(start, goal, load) is not None

    def _holding(self, start, goal, load: str) -> Optional[StationTable]:
        """Return the station table of ``load`` if it holds ``start`` to ``goal``, else None."""
        table = self.tables.get(load)  # read once: it may be set meanwhile
        held = table is not None and isinstance(start, str) and isinstance(goal, str) \
            and (start, goal) in table.entries
        return table if held else None

    def using(self, budget: Optional[float], sample_period: float) -> 'PlanningService':
        """Return the service with another budget and sample period, and the same tables."""
        planner = self.planner
        if planner.settings.sample_period != sample_period:
            planner = planner.with_sample_period(sample_period)
        return PlanningService(planner, budget=budget, tables=self.tables)

    def answer(self, start, goal, deadline: Optional[float] = None,
               load: str = LOADED, transfer: Optional[PlanResult] = None) -> PlanResult:
        """
        Return the verified answer from ``start`` to ``goal`` (stations or joint angles).

        ``deadline``: a ``time.monotonic()`` instant after which planning gives up with
        TIMEOUT. ``load``: the limit set (``Planner.plan``), which picks the station table.
        ``transfer``: the table's move between the stations of a port move
        (``lent_transfer``), when a service without the tables plans it. Raises
        PlanningError with the code of the first reason it cannot answer.
        """
        table = self._holding(start, goal, load)
        if table is not None:
            return table.answer(self.planner, start, goal)
        planner, budget = self._budgeted(deadline)
        if budget is not None:
            transfer = transfer or self.lent_transfer(start, goal, load)
            if transfer is not None:
                whole_curve(self.planner).for_load(load).keep(transfer)
        return _named(planner.plan(start, goal, deadline=deadline, budget=budget, load=load),
                      budget)

    def divert(self, trajectory, at: float, goal, label: str,
               deadline: Optional[float] = None, load: str = LOADED,
               leaves: Optional[float] = None) -> PlanResult:
        """
        Return the move from ``trajectory`` in motion at ``at`` to ``goal`` (``Planner.divert``).

        Its move from where the stop rests is planned as a request for joint angles is: with
        the budget by the whole-curve optimisation, or without by ``planner`` (the module).
        ``leaves``: the ``time.monotonic()`` instant the robot passes ``at``, if known.
        """
        planner, budget = self._budgeted(deadline)
        return _named(planner.divert(trajectory, at, goal, label, load, deadline, budget,
                                     leaves), budget)

    def _budgeted(self, deadline: Optional[float]) -> tuple:
        """
        Return (planner, budget s or None) for a request that no table answers (the module).

        Without a budget: ``planner``, None; with one: the whole-curve planner and the budget
        (never more than half of what is left before ``deadline``), or the corridor curve's
        planner and None where that leaves less than ``MIN_BUDGET``.
        """
        if self.budget is None:
            return self.planner, None
        budget = self.budget if deadline is None else \
            min(self.budget, 0.5 * (deadline - time.monotonic()))
        if budget < MIN_BUDGET:
            return _with_method(self.planner, KnotTiming), None
        return whole_curve(self.planner), budget

    def lent_transfer(self, start, goal, load: str = LOADED) -> Optional[PlanResult]:
        """
        Return the table's move between the stations of a port move, or None.

        A move from inside a port to inside another is planned as its ways through the
        ports and a transfer between the port mouths, the stations' retracted poses: when
        the table of ``load`` holds that station pair, its verified answer is that transfer
        (``Planner.keep``: ``answer`` lends it to the whole-curve planner), where the budget
        alone would make a slower one.
        """
        if not (isinstance(start, str) and isinstance(goal, str)) or not (
                start.endswith(INSIDE) or goal.endswith(INSIDE)):
            return None
        pair = tuple(station_name(name) for name in (start, goal))
        table = self._holding(*pair, load)
        if table is None:
            return None
        return table.answer(whole_curve(self.planner).for_load(load), *pair)


def _named(result: PlanResult, budget: Optional[float]) -> PlanResult:
    """Return a result that says the budget it was planned within (when it had one)."""
    return result if budget is None else replace(result,
                                                 metrics=dict(result.metrics, budget=budget))


def whole_curve(planner: Planner) -> Planner:
    """Return the planner with the whole-curve optimisation as its method."""
    return _with_method(planner, WholeCurve)


def _with_method(planner: Planner, method: Type[CurveMethod]) -> Planner:
    return planner.with_method(method)


def within_budget(station_request: bool, values: Mapping, budget_parameter) -> bool:
    """
    Return whether a recorded answer came from the time-budgeted optimisation.

    ``values``: the answer's result values; ``budget_parameter``: ``planning.optimise_budget``
    when the request arrived. A successful answer says so (``budget``); an error answer does
    not, so a joint request planned while the budget was above 0 counts as budgeted. A
    station request's error does not: what fails one (an unknown station, no path) does
    not depend on the budget.
    """
    if 'budget' in values:
        return _positive(values['budget'])
    return not station_request and _positive(budget_parameter)


def _positive(text) -> bool:
    try:
        return float(text) > 0.0
    except (TypeError, ValueError):
        return False
