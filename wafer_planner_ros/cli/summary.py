"""
How the tools word a plan's figures: the same units and rounding everywhere.

``wafer-plan`` words its own result, ``wafer-plan-client`` and ``wafer-review`` the values of
a node's ``~/result`` (strings: ``number`` and ``branches`` read them back, tolerating any
text); all through these functions, so a figure reads the same in each.
"""

import json
import math
from typing import Mapping, Optional, Sequence, Tuple

from wafer_planner_ros.geometry.kinematics import elbow_words


def cycle_text(cycle_time: float, initial: Optional[float] = None) -> str:
    """Return 'cycle time 1.586 s (λ-scaled start 4.196 s)': the paper's timing, the start."""
    text = f'cycle time {cycle_time:.3f} s'
    if initial is not None:
        text += f' (λ-scaled start {initial:.3f} s)'
    return text


def branches_text(branches: Sequence[Optional[int]]) -> str:
    """Return the elbow branches of the start and the goal in words, '->' between."""
    return ' -> '.join(elbow_words(b) or 'joint angles' for b in branches)


def clearance_text(metres: float) -> str:
    """Return 'min clearance 9.6 mm'."""
    return f'min clearance {metres * 1000.0:.1f} mm'


def ratios_text(ratios: Mapping[str, float]) -> str:
    """Return 'limit ratios: velocity 0.450, acceleration 0.801, ...'."""
    return 'limit ratios: ' + ', '.join(f'{name} {ratio:.3f}' for name, ratio in ratios.items())


def jerk_text(peak_jerk: Sequence[float], wafer_jerk: float) -> str:
    """Return 'peak jerk 168, 120, 90 rad/s³ (joints), wafer 12.3 m/s³'."""
    return (f"peak jerk {', '.join(f'{v:.0f}' for v in peak_jerk)} rad/s³ (joints), "
            f'wafer {wafer_jerk:.1f} m/s³')


def proof_text(certified: bool) -> str:
    """Return whether the curve is proven collision-free, in words."""
    return 'proven collision-free' if certified else 'NOT proven collision-free'


def number(text) -> Optional[float]:
    """Return a result's value as a finite float, None when it is missing or not one."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def branches(text) -> Tuple[Optional[int], Optional[int]]:
    """Return a result's (start, goal) elbow branches: +1, -1 or None (joints, unknown)."""
    try:
        found = json.loads(text)
    except (TypeError, ValueError):
        return None, None
    if not isinstance(found, list) or len(found) != 2:
        return None, None
    return tuple(b if b in (1, -1) and not isinstance(b, bool) else None for b in found)
