"""
The planner of one cell and roadmap: a request -> its ends -> the fastest verified answer.

``Planner.plan(start, goal)`` takes a station name or three joint angles for each end
(``endpoints``). Between ends outside the ports every elbow-branch combination is searched
(``candidates``); a move into or out of a port is its ways through the ports and a transfer
between the port mouths (``through``), never slower, planned without a time budget, than
stopping at the mouths (``Planner.stop_and_go``): that bound every blended combination must
beat, and the answer when none does. What serves later requests (transfers, ways) is kept
(``legs``). Every returned trajectory has passed ``verify``; a request that cannot be
answered raises ``PlanningError`` with its code.
"""

from dataclasses import replace
import time
from typing import Optional, Tuple, Type

from wafer_planner_ros.cell.limits import LOADS
from wafer_planner_ros.cell.schema import brief
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner import candidates
from wafer_planner_ros.planner.endpoints import Endpoint, endpoint, only_branch
from wafer_planner_ros.planner.legs import leg_key, Legs
from wafer_planner_ros.planner.optima import Optima
from wafer_planner_ros.planner.result import PlanResult
from wafer_planner_ros.planner.settings import PlannerSettings
from wafer_planner_ros.planner.stop import divert, prepare, stop
from wafer_planner_ros.planner.through import through
from wafer_planner_ros.trajectory.methods import CurveMethod


class Planner:
    """Plans on one cell with one roadmap."""

    def __init__(self, cell, roadmap, settings: PlannerSettings = PlannerSettings()):
        """Keep the cell, its roadmap and the settings."""
        self.cell = cell
        self.roadmap = roadmap
        self.settings = settings
        self.method = settings.method(cell, settings.timing, settings.shape)
        self.legs = Legs()
        """The transfers between port mouths planned so far, and the ways through ports."""
        self._optima = {}
        """Limit set -> its ``Optima``, shared by the planners of every set and method."""
        self._by_load = {cell.robot.load: self}
        self._by_method = {settings.method: self}

    @property
    def load(self) -> str:
        """Return the limit set this planner plans against (``cell.limits``)."""
        return self.cell.robot.load

    def for_load(self, load: str) -> 'Planner':
        """Return the planner of this cell and roadmap against the limit set ``load``."""
        if load not in self._by_load:
            if load not in LOADS:
                raise PlanningError(ErrorCode.INVALID_REQUEST,
                                    f'unknown load {brief(load)}: one of {", ".join(LOADS)}')
            planner = Planner(self.cell.with_load(load), self.roadmap, self.settings)
            planner._by_load = self._by_load  # one planner per limit set, shared
            planner._optima = self._optima
            self._by_load[load] = planner
        return self._by_load[load]

    @property
    def optima(self) -> Optima:
        """
        Return the optima of this limit set answered so far or handed over (``optima``).

        Drafts for requests near them, one library per limit set for every curve method.
        """
        optima = self._optima.get(self.load)
        return optima if optima is not None else self._optima.setdefault(self.load, Optima())

    @property
    def libraries(self) -> dict:
        """Return every limit set's ``optima`` made so far, by limit set."""
        return dict(self._optima)

    def with_method(self, method: Type[CurveMethod]) -> 'Planner':
        """Return the planner of this cell, roadmap and limit set with another curve method."""
        if method not in self._by_method:
            planner = Planner(self.cell, self.roadmap, replace(self.settings, method=method))
            planner._optima = self._optima
            planner._by_method = self._by_method
            self._by_method[method] = planner
        return self._by_method[method]

    def with_sample_period(self, period: float) -> 'Planner':
        """Return a planner like this one sampling answers every ``period`` s (its optima)."""
        planner = Planner(self.cell, self.roadmap, replace(self.settings, sample_period=period))
        planner._optima = self._optima
        return planner

    def endpoint(self, value, role: str) -> Endpoint:
        """Resolve a station name or joint angles on this cell (``endpoints.endpoint``)."""
        return endpoint(self.cell, value, role)

    def plan(self, start, goal, deadline: Optional[float] = None,
             branches: Optional[Tuple[Optional[int], Optional[int]]] = None,
             budget: Optional[float] = None, load: Optional[str] = None) -> PlanResult:
        """
        Return the verified trajectory from start to goal with the shortest cycle time.

        ``load``: the limit set, ``LOADED`` (a wafer on the blade: the wafer limit holds)
        or ``EMPTY`` (none: joint limits only); None: this planner's (``load``). An empty
        move made with a wafer on the blade can slide it.

        ``deadline``: a ``time.monotonic()`` instant after which the request gives up with
        TIMEOUT. ``branches``: plan only this (start, goal) elbow-branch combination (None
        for joint angles), e.g. to see what each one costs. ``budget``: seconds from now
        after which a curve method that improves step by step returns the best curve it has
        (verified like any other), and the elbow-branch combinations not yet finished are
        given up when one is. Raises PlanningError with the code of the first reason it
        cannot answer.
        """
        if load is not None and load != self.load:
            return self.for_load(load).plan(start, goal, deadline, branches, budget)
        begun = time.perf_counter()
        until = None if budget is None else time.monotonic() + budget
        return self._planned(*self._ends_of(start, goal, branches), deadline, until, begun)

    def stop_and_go(self, start, goal, deadline: Optional[float] = None,
                    load: Optional[str] = None,
                    branches: Optional[Tuple[Optional[int], Optional[int]]] = None
                    ) -> PlanResult:
        """
        Return the move through a port that stops at each port mouth, verified (``through``).

        The same move as ``plan`` without blending the ways through the ports into the
        transfer: straight out of the start's port to rest at its mouth, the transfer from
        rest to rest, straight into the goal's port. ``load`` and ``branches`` as for
        ``plan``. Raises PlanningError: INVALID_REQUEST when neither end is inside a port,
        else the first reason none could be planned.
        """
        if load is not None and load != self.load:
            return self.for_load(load).stop_and_go(start, goal, deadline, branches=branches)
        begun = time.perf_counter()
        a, b = self._ends_of(start, goal, branches)
        if not (a.channels or b.channels):
            raise PlanningError(ErrorCode.INVALID_REQUEST,
                                f'{a.label} -> {b.label} does not stop on its way: neither '
                                'end is inside a port')
        return through(self, a, b, deadline, None, begun, blend=False)

    def stop(self, trajectory, at: float, label: str = 'the move',
             load: Optional[str] = None, verified=None, ahead=None) -> PlanResult:
        """
        Return the controlled stop of ``trajectory`` from ``at`` s on its path (``stop``).

        ``load``: the limit set it keeps (None: this planner's); a stop keeps the set the
        move was planned against. ``verified``: the verification the move passed when it
        was answered, held since; ``ahead``: its stop made ahead, from a moment no earlier
        than ``at`` (both ``stop.stop``). Raises PlanningError: OUTSIDE_TRAJECTORY, AT_REST
        or VERIFICATION_FAILED.
        """
        if load is not None and load != self.load:
            return self.for_load(load).stop(trajectory, at, label, verified=verified,
                                            ahead=ahead)
        return stop(self, trajectory, at, label, verified, ahead)

    def prepare_stop(self, trajectory, moment: float, verified, load: Optional[str] = None,
                     made=None):
        """
        Return the stop of ``trajectory`` from ``moment`` made ahead of a request, or None.

        Verified with ``verified``, the (proven) verification the move passed, under the
        limit set ``load`` (None: this planner's); for ``stop``'s ``ahead`` (``prepare``:
        ``made``, the stop found elsewhere, or None).
        """
        if load is not None and load != self.load:
            return self.for_load(load).prepare_stop(trajectory, moment, verified, made=made)
        return prepare(self, trajectory, moment, verified, made)

    def divert(self, trajectory, at: float, goal, label: str = 'the move',
               load: Optional[str] = None, deadline: Optional[float] = None,
               budget: Optional[float] = None, leaves: Optional[float] = None) -> PlanResult:
        """
        Return the move from ``trajectory`` at ``at`` s to ``goal``, starting in motion.

        One curve from the moving state where one is found, else the controlled stop then
        the move from rest to ``goal``, as one verified trajectory (``stop.divert``).
        ``load``, ``deadline``, ``budget`` as for ``plan``; ``leaves``: the
        ``time.monotonic()`` instant the robot passes ``at`` (``stop.divert``).
        """
        if load is not None and load != self.load:
            return self.for_load(load).divert(trajectory, at, goal, label, None, deadline,
                                              budget, leaves)
        return divert(self, trajectory, at, goal, label, deadline,
                      None if budget is None else time.monotonic() + budget, leaves)

    def planned(self, start, goal, deadline: Optional[float] = None,
                until: Optional[float] = None) -> PlanResult:
        """Return ``plan``'s answer with ``until`` a ``time.monotonic()`` instant."""
        begun = time.perf_counter()
        return self._planned(*self._ends_of(start, goal, None), deadline, until, begun)

    def transfer(self, start: Endpoint, goal: Endpoint, deadline: Optional[float],
                 until: Optional[float] = None) -> PlanResult:
        """
        Return the move from ``start`` to ``goal``, each of one configuration, planned once.

        A transfer between two port mouths serves every move through those ports: a kept
        answer (``keep``) or a kept draft, verified when first asked for (and planned again
        if it fails), else planned now. One planned within a budget (``until``) is not kept.
        """
        key = leg_key(start.configs[0][1], goal.configs[0][1],
                      (start.configs[0][0], goal.configs[0][0]))
        leg, draft = self.legs.leg_or_draft(key)
        if draft is not None:
            leg = candidates.drafted(self, *draft)
        if leg is None:
            leg = self._planned(start, goal, deadline, until, time.perf_counter())
        return leg

    def keep(self, result: PlanResult) -> None:
        """
        Keep a verified answer planned without a budget as a transfer between its ends.

        A move through a port whose mouths are its ends, on its branches, takes it as its
        transfer (``transfer``) instead of planning one.
        """
        self.legs.keep('legs', leg_key(result.start_q, result.goal_q, result.branches),
                       result)

    def holds_transfer(self, mouths, branches) -> bool:
        """Return whether the transfer between two mouths on their branches is kept."""
        return self.legs.holds('legs', leg_key(*mouths, branches))

    def _ends_of(self, start, goal, branches) -> Tuple[Endpoint, Endpoint]:
        """Return the resolved ends of a request, each on its branch of ``branches`` if given."""
        a, b = self.endpoint(start, 'start'), self.endpoint(goal, 'goal')
        if branches is None:
            return a, b
        return tuple(only_branch(end, elbow, role) for end, elbow, role in
                     ((a, branches[0], 'start'), (b, branches[1], 'goal')))

    def _planned(self, a: Endpoint, b: Endpoint, deadline: Optional[float],
                 until: Optional[float], begun: float) -> PlanResult:
        """Return the fastest verified answer between two resolved ends (``plan``)."""
        if a.channels or b.channels:
            return through(self, a, b, deadline, until, begun, blend=True)
        return candidates.search(self, a, b, deadline, until, begun)
