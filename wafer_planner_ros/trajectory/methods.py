"""
Ways to shape and time a curve through a safe corridor.

The planner gives a method the corridor of every elbow-branch combination and asks for a
``Draft`` (its ``estimate`` orders the combinations), then finishes the drafts most
promising first, telling each the cycle time it need not beat. A finished curve that fails
verification is replaced by its ``fallback`` when it has one. A method returns a curve
(any ``Trajectory``) with its own figures; the planner verifies it. Methods are named by
``PlannerSettings.method``; ``METHODS`` lists them.
"""

from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
from typing import ClassVar, Mapping, Optional, Tuple

from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.corridor import Corridor
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.shape import optimise_shape
from wafer_planner_ros.trajectory.timing import optimise
from wafer_planner_ros.trajectory.timing_problem import scaled_start, TimingProblem
from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings


@dataclass(frozen=True, eq=False)
class Draft:
    """A method's starting point for one corridor."""

    estimate: float
    """s: the cycle time of the starting point (what finishing it improves on)."""
    work: object
    """The method's own state, handed back to ``finish``."""


@dataclass(frozen=True, eq=False)
class Shaped:
    """A finished curve, not yet verified."""

    trajectory: Trajectory
    initial_cycle_time: float
    """s: the cycle time the method started from."""
    metrics: Mapping = field(default_factory=dict)
    """The method's own figures (solver iterations and the like)."""
    warnings: Tuple[str, ...] = ()
    fallback: Optional['Shaped'] = None
    """What to return instead if this curve fails verification (the curve it started
    from), if anything."""


class CurveMethod(ABC):
    """A way to shape and time a curve through a corridor for one cell's robot."""

    name: ClassVar[str]

    def __init__(self, cell, settings: TimingSettings, shape: ShapeSettings = ShapeSettings()):
        """Keep the cell and the optimisers' tuning."""
        self.cell = cell
        self.settings = settings
        self.shape = shape

    @abstractmethod
    def draft(self, corridor: Corridor) -> Draft:
        """Return the starting point for a corridor."""

    @abstractmethod
    def finish(self, draft: Draft, give_up_above: Optional[float] = None,
               until: Optional[float] = None) -> Optional[Shaped]:
        """
        Return the finished curve; None once it shows it cannot beat ``give_up_above`` s.

        ``until``: a ``time.monotonic()`` instant by which a method that improves a curve
        step by step returns the best it has.
        """


class KnotTiming(CurveMethod):
    """
    The paper's timing (sections 4.3 and 5).

    The corridor's control points stay where they are; the span durations are optimised
    from the λ-scaled uniform timing (Eq. 12).
    """

    name = 'knot-timing'

    def draft(self, corridor: Corridor) -> Draft:
        """Return the λ-scaled uniform timing of the corridor's control points."""
        problem = TimingProblem(corridor.control_points, self.cell.robot, self.settings)
        start = scaled_start(problem)
        return Draft(float(start[0].sum()), (problem, start))

    def finish(self, draft: Draft, give_up_above: Optional[float] = None,
               until: Optional[float] = None) -> Optional[Shaped]:
        """Return the spline with optimised span durations (``timing.optimise``)."""
        problem, start = draft.work
        timing = optimise(problem, start, give_up_above)
        if timing is None:
            return None
        warnings = () if timing.optimised else (
            f'time optimisation failed ({timing.message}); returning the λ-scaled timing',)
        metrics = {'lambda': timing.scale, 'optimised': timing.optimised,
                   'solver_iterations': timing.iterations,
                   'constraint_rounds': timing.rounds, 'wafer_samples': timing.samples}
        return Shaped(CubicBSpline.from_intervals(problem.points, timing.intervals),
                      draft.estimate, metrics, warnings)


class WholeCurve(KnotTiming):
    """
    The control points move with the span durations (``shape.optimise_shape``).

    The draft is the corridor curve with optimised knot times (``KnotTiming``: feasible by
    construction, and near the answer, so SLSQP starts close; its cycle time orders the
    elbow-branch combinations better than the λ-scaled start does); the curve returned is
    proven collision-free on its own (``proof``), not by the corridor, and falls back on
    the corridor curve if it fails verification.
    """

    name = 'whole-curve'

    def draft(self, corridor: Corridor) -> Draft:
        """Return the corridor curve with optimised knot times."""
        start = super().draft(corridor)
        timed = super().finish(start)
        return Draft(timed.trajectory.duration, (start.estimate, timed))

    def finish(self, draft: Draft, give_up_above: Optional[float] = None,
               until: Optional[float] = None) -> Optional[Shaped]:
        """Return the fastest proven curve the whole-curve optimisation found (by ``until``)."""
        initial, timed = draft.work
        shaped = optimise_shape(timed.trajectory, self.cell, self.shape, self.settings,
                                give_up_above, until)
        if shaped is None:
            return None
        warnings = () if shaped.improved else (
            f'whole-curve optimisation found no faster proven curve ({shaped.message}); '
            'returning the corridor curve',)
        metrics = dict(timed.metrics, optimised=shaped.improved,
                       shape_iterations=shaped.iterations, shape_rounds=shaped.rounds,
                       spans=shaped.spans, corridor_cycle_time=timed.trajectory.duration)
        fallback = replace(timed, warnings=timed.warnings + (
            "the whole-curve optimisation's curve failed verification; returning the "
            'corridor curve',))
        return Shaped(shaped.trajectory, initial, metrics, timed.warnings + warnings,
                      fallback)


METHODS = {method.name: method for method in (KnotTiming, WholeCurve)}
"""The methods by name."""
