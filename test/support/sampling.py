"""What a published trajectory's sample times are: every period, and the curve's breaks."""

import numpy as np

BREAK_GAP = 1e-3
"""s: a multiple of the period may give way to a break this near it (``Trajectory.samples``)."""


def sampled_every(times, period: float) -> bool:
    """
    Return whether ``times`` are a sampling every ``period`` s (with other times between).

    Every multiple of ``period`` before the end a time, or given way to another time within
    ``BREAK_GAP``; so no two times more than ``period`` + ``BREAK_GAP`` apart.
    """
    times = np.asarray(times, float)
    multiples = np.arange(0.0, times[-1] - 1e-9, period)
    nearest = np.abs(times[None, :] - multiples[:, None]).min(axis=1)
    return bool(np.all(nearest < BREAK_GAP + 1e-9)
                and np.diff(times).max() <= period + BREAK_GAP + 1e-9)
