"""
The figure of a controlled stop against the abrupt hold a controller would make instead.

For whoever decides whether to trust a stop (``trajectory.stopping``): the cell with the
move's path, where it was stopped and where each way of stopping comes to rest; the wafer's
acceleration on x and y, of the move up to the moment, then of the controlled stop and of
the abrupt hold (``hold_motion``: each joint braked alone at its acceleration limit, off
the path), against the wafer limit; and the joint speeds of both (along the path the stop's
joints all come to rest at one instant; the hold brings each to rest at its own, leaving it).
"""

import io
from typing import Optional

from matplotlib.figure import Figure
from matplotlib.lines import Line2D
import numpy as np
from PIL import Image

from wafer_planner_ros.plotting import _emptiest_corner, _peak, _wrapped, body_outline
from wafer_planner_ros.plotting import draw_cell, draw_robot, draw_stations, motion_label
from wafer_planner_ros.trajectory.stopping import hold_motion

MOVE, STOP, HOLD = '0.35', 'tab:green', 'tab:red'
"""Colours of the move up to the stop, the controlled stop and the abrupt hold."""
_JOINT_STYLES = ('-', '--', ':', '-.')
_WAFER_STYLES = {'x': '-', 'y': '--', '|a|': ':'}
_SAMPLES = 1500
"""Samples of each of the move, the stop and the hold."""
COLOURS = 256
"""Colours of the PNG's palette: a third of the bytes of full colour, alike to the eye."""


def plot_stop(cell, move_result, stop_result, at: float, path, dpi: int = 100) -> Figure:
    """
    Write a PNG of ``move_result``'s move stopped at ``at`` s (``stop_result``) and held.

    Left, the cell: the move's wafer-centre path (the part before ``at`` solid), the stop's
    stretch of it and the hold's own trace, with the robot where the stop begins and where
    the stop and the hold come to rest. Right, over the move's time: the wafer acceleration
    on x and y (and |a| under a limit on it) of the move to ``at``, of the stop and of the
    hold from ``at``, the limit drawn and its band shaded; below, the joint speeds of the
    three. The title names the move, the moment, the stop's time to rest and its share of
    the wafer limit, and the hold's time to rest and peak against the limit.
    """
    robot = cell.with_load(move_result.load).robot
    move, stop = move_result.trajectory, stop_result.trajectory
    series = {}
    t = np.linspace(0.0, at, _SAMPLES)
    series[MOVE] = (t, *move.evaluate_orders(t, range(3)))
    t = np.linspace(0.0, stop.duration, _SAMPLES)
    series[STOP] = (at + t, *stop.evaluate_orders(t, range(3)))
    t, q, qd, qdd = hold_motion(move, at, robot, _SAMPLES)
    series[HOLD] = (at + t, q, qd, qdd)
    wafer = {k: robot.arm.wafer_acceleration(*s[1:]) for k, s in series.items()}
    limit = robot.wafer_limit

    fig = Figure(figsize=(14, 7.6))
    grid = fig.add_gridspec(2, 2, width_ratios=(1.0, 1.05), left=0.055, right=0.985,
                            bottom=0.075, top=0.87, hspace=0.3, wspace=0.17)
    _draw_cell(fig.add_subplot(grid[:, 0]), cell, robot, move, at, series)
    wafer_axis = fig.add_subplot(grid[0, 1])
    _draw_wafer(wafer_axis, series, wafer, limit)
    joints_axis = fig.add_subplot(grid[1, 1], sharex=wafer_axis)
    _draw_speeds(joints_axis, robot, series)
    for axis in (wafer_axis, joints_axis):
        axis.axvline(at, color='black', linewidth=0.8)
        axis.grid(alpha=0.3)
    wafer_axis.text(at, 0.02, f'stop at {at:.3g} s ', transform=wafer_axis.get_xaxis_transform(),
                    fontsize=8, ha='right', va='bottom')
    fig.suptitle(_wrapped(_title(move_result, at, series, wafer, limit), 170), fontsize=11,
                 parse_math=False)
    png = io.BytesIO()
    fig.savefig(png, dpi=dpi, format='png')
    png.seek(0)
    Image.open(png).convert('RGB').quantize(COLOURS).save(path, format='png', optimize=True)
    return fig


def _title(move_result, at, series, wafer, limit) -> str:
    """Return the figure's title: the move, the moment, the stop's and the hold's figures."""
    ends = motion_label(move_result.start.label, move_result.goal.label, move_result.branches)
    stop_rest = series[STOP][0][-1] - at
    hold_rest = series[HOLD][0][-1] - at
    title = (f'{ends}, stopped at {at:.3g} s: the controlled stop, on the path, at rest after '
             f'{stop_rest:.3f} s')
    if limit is None:
        return title + f'; the abrupt hold, off the path, at rest after {hold_rest:.3f} s'
    peak = float(np.abs(wafer[HOLD]).max())
    return (title + f' (wafer {_ratio(wafer[STOP], limit):.3f} × its limit)\n'
            f'the abrupt hold (each joint braked alone at its acceleration limit), off the '
            f'path: at rest after {hold_rest:.3f} s, wafer peak {peak:.2f} m/s², '
            f'{_ratio(wafer[HOLD], limit):.1f} × its {_limit_text(limit)} limit')


def _ratio(acceleration: np.ndarray, limit) -> float:
    """Return the largest share of the wafer limit of accelerations (N, 2): x, y (, |a|)."""
    ratio = _peak(np.abs(acceleration) / limit.xy)
    if limit.norm is not None:
        ratio = max(ratio, _peak(np.hypot(*acceleration.T) / limit.norm))
    return ratio


def _limit_text(limit) -> str:
    """Return e.g. '0.981 m/s²' (x and y alike) or '0.981, 0.5 m/s² (x, y)'."""
    x, y = (float(v) for v in limit.xy)
    text = f'{x:.3g} m/s²' if x == y else f'{x:.3g}, {y:.3g} m/s² (x, y)'
    return text if limit.norm is None else f'{text}, |a| {limit.norm:.3g} m/s²'


def _draw_cell(ax, cell, robot, move, at: float, series) -> None:
    """Draw the cell, the move's wafer path, the stop's and the hold's, and the robot."""
    draw_cell(ax, cell)
    draw_stations(ax, cell)
    arm = robot.arm
    whole = arm.wafer_center(move.evaluate(np.linspace(0.0, move.duration, _SAMPLES)))
    ax.plot(*whole.T, color=MOVE, linestyle=':', linewidth=1.2,
            label="the move's path (not followed after the stop)")
    drawn = [whole]
    labels = {MOVE: f'the move to {at:.3g} s', STOP: 'controlled stop (on the path)',
              HOLD: 'abrupt hold (off the path)'}
    for colour, (t, q, _, _) in series.items():
        centre = arm.wafer_center(q)
        drawn.append(centre)
        ax.plot(*centre.T, color=colour, linewidth=2.2 if colour != MOVE else 1.6,
                label=labels[colour] + ('' if colour == MOVE else
                                        f', at rest after {t[-1] - at:.3f} s'))
    start = series[STOP][1][0]
    draw_robot(ax, robot, start, colour='black', linewidth=1.2)
    ax.plot(*arm.wafer_center(start), marker='o', color='black', linestyle='', markersize=6)
    for colour in (STOP, HOLD):
        rest = series[colour][1][-1]
        draw_robot(ax, robot, rest, colour=colour, linewidth=1.2)
        ax.plot(*arm.wafer_center(rest), marker='s', color=colour, linestyle='', markersize=6)
        drawn += [body_outline(robot, rest, k) for k in range(4)]
    drawn += [body_outline(robot, start, k) for k in range(4)]
    handles, _ = ax.get_legend_handles_labels()
    handles.append(Line2D([], [], color='black', marker='o', linewidth=1.2,
                          label=f'robot at {at:.3g} s (the stop begins)'))
    handles.append(Line2D([], [], color='0.4', marker='s', linestyle='', label='at rest'))
    ax.legend(handles=handles, loc=_emptiest_corner(ax, np.vstack(drawn)), fontsize=8.5,
              framealpha=0.9)
    ax.set_title('wafer-centre paths and the robot where the stop begins and at rest',
                 fontsize=10)


def _draw_wafer(axis, series, wafer, limit: Optional[object]) -> None:
    """Draw the wafer acceleration on x and y (and |a|) of each motion, the limit shaded."""
    for colour, (t, *_) in series.items():
        values = wafer[colour]
        components = {'x': values[:, 0], 'y': values[:, 1]}
        if limit is not None and limit.norm is not None:
            components['|a|'] = np.hypot(values[:, 0], values[:, 1])
        for name, value in components.items():
            axis.plot(t, value, color=colour, linestyle=_WAFER_STYLES[name], linewidth=1.3)
    handles = [Line2D([], [], color='0.2', linestyle=style, label=f'a_{name}' if len(name) == 1
                      else name) for name, style in _WAFER_STYLES.items()
               if len(name) == 1 or (limit is not None and limit.norm is not None)]
    if limit is not None:
        bounds = sorted({float(v) for v in limit.xy})
        axis.axhspan(-bounds[0], bounds[0], color='tab:blue', alpha=0.08)  # within both
        for bound in bounds:
            for sign in (-1.0, 1.0):
                axis.axhline(sign * bound, color='black', linestyle='--', linewidth=0.8)
        if limit.norm is not None:
            axis.axhline(limit.norm, color='black', linestyle='-.', linewidth=0.8)
        handles.append(Line2D([], [], color='black', linestyle='--', linewidth=0.8,
                              label=f'limit ({_limit_text(limit)})'))
        stop, hold = _ratio(wafer[STOP], limit), _ratio(wafer[HOLD], limit)
        axis.text(0.01, 0.97, f'controlled stop: peak {stop:.1%} of the limit\n'
                  f'abrupt hold: peak {float(np.abs(wafer[HOLD]).max()):.2f} m/s², '
                  f'{hold:.1f} × the limit', transform=axis.transAxes, ha='left', va='top',
                  fontsize=8.5, bbox={'facecolor': 'white', 'edgecolor': 'none', 'pad': 1.5})
    axis.legend(handles=handles + _motion_handles(), fontsize=8, ncol=len(handles) + 3,
                loc='lower right', bbox_to_anchor=(1.0, 1.0), frameon=False, borderaxespad=0.2)
    axis.set_ylabel('wafer acceleration (m/s²)' if limit is not None else
                    'blade acceleration (m/s², empty: no limit)')


def _draw_speeds(axis, robot, series) -> None:
    """Draw each joint's speed of each motion: one colour a motion, one line style a joint."""
    for colour, (t, _, qd, _) in series.items():
        for j in range(qd.shape[1]):
            axis.plot(t, qd[:, j], color=colour, linestyle=_JOINT_STYLES[j % 4], linewidth=1.3)
    handles = [Line2D([], [], color='0.2', linestyle=_JOINT_STYLES[j % 4], label=name)
               for j, name in enumerate(robot.joint_names)]
    axis.legend(handles=handles + _motion_handles(), fontsize=8, ncol=len(handles) + 3,
                loc='lower right', bbox_to_anchor=(1.0, 1.0), frameon=False, borderaxespad=0.2)
    axis.set_ylabel('joint speed (rad/s)')
    axis.set_xlabel("t (s, from the move's start)")


def _motion_handles() -> list:
    """Return the legend entries of the three motions' colours."""
    return [Line2D([], [], color=colour, linewidth=2, label=label) for colour, label in
            ((MOVE, 'move'), (STOP, 'controlled stop'), (HOLD, 'abrupt hold'))]
