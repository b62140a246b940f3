"""How a planner makes its trajectories: the pipeline's options, checked once."""

from dataclasses import dataclass
from typing import Type

from wafer_planner_ros.trajectory.methods import CurveMethod, KnotTiming, METHODS
from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings

SAMPLE_PERIOD_RANGE = (0.001, 1.0)
"""s: the shortest and longest step between returned samples (the verification's is 1 ms)."""


@dataclass(frozen=True)
class PlannerSettings:
    """How trajectories are made. ``PlannerSettings.paper()`` is the paper's pipeline."""

    sample_period: float = 0.01
    """Seconds between the returned samples (the exact final point is added)."""
    shortcut: bool = True
    """Shorten the roadmap path with certified shortcuts (beyond the paper)."""
    per_body_boxes: bool = True
    """Size the safe boxes per body (beyond the paper; False: Eq. 3)."""
    extra_points: int = 1
    """Control points added on every straight stretch (beyond the paper)."""
    method: Type[CurveMethod] = KnotTiming
    """How the curve through the corridor is shaped and timed: a ``CurveMethod`` class
    (``trajectory.methods``), or its name (``METHODS``: where settings come from text)."""
    timing: TimingSettings = TimingSettings()
    """The time optimiser's tuning."""
    shape: ShapeSettings = ShapeSettings()
    """The whole-curve optimiser's tuning."""

    def __post_init__(self):
        """Reject unusable settings."""
        low, high = SAMPLE_PERIOD_RANGE
        if not (isinstance(self.sample_period, (int, float))
                and low <= self.sample_period <= high):
            raise ValueError(f'sample_period must be in [{low}, {high}] s, got '
                             f'{self.sample_period!r}')
        if not isinstance(self.extra_points, int) or self.extra_points < 0:
            raise ValueError(f'extra_points must be an integer >= 0, got {self.extra_points!r}')
        method = METHODS.get(self.method) if isinstance(self.method, str) else self.method
        if not (isinstance(method, type) and issubclass(method, CurveMethod)):
            raise ValueError(f'method must be one of {", ".join(sorted(METHODS))}, got '
                             f'{self.method!r}')
        object.__setattr__(self, 'method', method)  # frozen: the class, whatever was given

    @classmethod
    def paper(cls, sample_period: float = 0.01) -> 'PlannerSettings':
        """Return the settings of the paper's exact pipeline, for comparison."""
        return cls(sample_period=sample_period, shortcut=False, per_body_boxes=False,
                   extra_points=0)
