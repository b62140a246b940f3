"""The time optimiser's tuning: one frozen set of values, the defaults measured to pay."""

from dataclasses import dataclass


@dataclass(frozen=True)
class TimingSettings:
    """How the knot intervals are optimised (``trajectory.timing``)."""

    margin: float = 0.999
    """Limits are tightened by this factor inside the optimiser, so that what lies between
    dense samples stays below the true limits that verification applies."""
    min_interval: float = 1e-3
    """s: the shortest span (Eq. 10 read as a small positive lower bound)."""
    dense_step: float = 1e-3
    """s: the step of the dense check of every answer."""
    max_rounds: int = 4
    """Solves with added samples at most (8 gave cycles at most 0.55 % shorter on 108
    problems, at 1.4 x the time)."""
    samples_per_span: int = 1
    """Wafer-acceleration samples per span in the first round (1: the paper's, every knot)."""
    rescale_tolerance: float = 1e-3
    """Samples stop being added once Eq. 12 would slow the answer by less than this."""
    ftol: float = 1e-5
    """s: SLSQP's stopping precision on the total time."""
    give_up_margin: float = 0.02
    """A round's optimum this much above the best so far gives the problem up. More samples
    only add constraints, so a round's optimum is about a lower bound of the final one: on
    the 3 test cells' station pairs it was at most 0.4 % above it."""
    active: float = 1.0 - 0.7 ** 2
    """Control-point constraints at 70 % of their limit or more are kept in the solver."""
    max_iterations: int = 200
    """SLSQP iterations per round at most."""
