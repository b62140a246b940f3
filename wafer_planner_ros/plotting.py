"""
Figures of the cell, the roadmap and the motions.

The enclosure with the robot and the roadmap in joint space (paper Figs. 4-5); a motion
with its joint and wafer profiles against the limits (Figs. 10-13); the ends of a refused
request with the bodies that collide. Each ``plot_*`` function writes a PNG and returns the
figure. The stations are labelled in every drawing of the cell, the joints named as in the
cell file, and the elbow branches in words (``geometry.kinematics.ELBOW_WORDS``).
"""

import textwrap
from typing import Optional, Sequence

from matplotlib import colormaps
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Polygon
import numpy as np

from wafer_planner_ros.cell.limits import LOADED
from wafer_planner_ros.geometry.contacts import BodyContact, colliding
from wafer_planner_ros.geometry.kinematics import elbow_words
from wafer_planner_ros.roadmap.graph import SAMPLER_NAMES
from wafer_planner_ros.trajectory.approach import Approach, on_curve, on_samples

_SAMPLER_COLOURS = ('tab:blue', 'tab:orange', 'tab:green')
_ANGLES = np.linspace(0.0, 2.0 * np.pi, 64)
_CLOSEST = 'black'
"""Colour of the robot at the closest approach and of its mark."""
_COLLIDING = 'red'
"""Colour of a body in collision and of the outline it collides with."""


def capsule_outline(a: np.ndarray, b: np.ndarray, radius: float, n: int = 16) -> np.ndarray:
    """Return the outline (K, 2) of the capsule swept by ``radius`` along a-b."""
    heading = np.arctan2(*(b - a)[::-1]) if np.any(b != a) else 0.0
    arc = np.linspace(-np.pi / 2, np.pi / 2, n)
    end = b + radius * np.column_stack([np.cos(heading + arc), np.sin(heading + arc)])
    start = a + radius * np.column_stack([np.cos(heading + np.pi + arc),
                                          np.sin(heading + np.pi + arc)])
    return np.vstack([end, start, end[:1]])


def body_outline(robot, q: np.ndarray, body: int) -> np.ndarray:
    """Return the outline (K, 2) of one body at q: link 0-2 (a capsule) or 3 (the wafer)."""
    points = robot.arm.joint_points(np.asarray(q, float))
    if body == 3:  # the wafer, or the empty end effector's envelope
        return points[3] + robot.end_radius * np.column_stack([np.cos(_ANGLES),
                                                               np.sin(_ANGLES)])
    return capsule_outline(points[body], points[body + 1], robot.link_radii[body])


def motion_label(start: str, goal: str, branches=(None, None)) -> str:
    """Return e.g. 'loadport2 (elbow right) -> loadlock1 (elbow left)' (no words: joints)."""
    ends = []
    for label, elbow in zip((start, goal), branches):
        words = elbow_words(elbow)
        ends.append(f'{label} ({words})' if words else label)
    return ' -> '.join(ends)


def draw_cell(ax, cell) -> None:
    """Draw the boundary and obstacles."""
    ring = np.vstack([cell.boundary, cell.boundary[:1]])
    ax.plot(ring[:, 0], ring[:, 1], color='black', linewidth=2)
    for obstacle in cell.obstacles:
        ax.fill(obstacle[:, 0], obstacle[:, 1], color='0.6', edgecolor='black')
    ax.plot(*cell.robot.base, marker='+', color='black', markersize=10)
    ax.set_aspect('equal')
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')


def draw_stations(ax, cell, colours: Optional[Sequence] = None) -> None:
    """
    Mark every station at its wafer centre with its name (grey, or one colour each).

    A station's port is drawn as its axis, dashed, from the retracted pose's wafer centre to
    the pick/place pose's, which is marked by a dot.
    """
    for i, (name, station) in enumerate(sorted(cell.stations.items())):
        colour = '0.35' if colours is None else colours[i]
        centre = cell.robot.arm.wafer_center(station.configs[0].q)
        ax.plot(*centre, marker='x', color=colour, markersize=6, linestyle='')
        if station.port is not None:
            axis = np.array([station.port.retracted, station.port.inside_center])
            ax.plot(*axis.T, color=colour, linestyle='--', linewidth=1.0)
            ax.plot(*axis[1], marker='.', color=colour, markersize=6, linestyle='')
        ax.annotate(name, centre, xytext=(4, 4), textcoords='offset points', fontsize=8,
                    color=colour, bbox={'facecolor': 'white', 'edgecolor': 'none',
                                        'alpha': 0.7, 'pad': 0.5})


def draw_robot(ax, robot, q: np.ndarray, colour='tab:blue', alpha=1.0, wafer=True,
               linewidth=1.0) -> None:
    """Draw the link capsules and the wafer of the robot at configuration q."""
    draw_robots(ax, robot, [q], [colour], alpha, wafer, linewidth)


def draw_robots(ax, robot, configurations, colours, alpha=1.0, wafer=True,
                linewidth=1.0) -> None:
    """Draw the robot at each configuration in its colour (two collections: quick to draw)."""
    links, link_colours, wafers, wafer_colours = [], [], [], []
    for q, colour in zip(configurations, colours):
        links += [body_outline(robot, q, k) for k in range(3)]
        link_colours += [colour] * 3
        if wafer:
            wafers.append(body_outline(robot, q, 3))
            wafer_colours.append(colour)
    ax.add_collection(LineCollection(links, colors=link_colours, alpha=alpha,
                                     linewidths=linewidth))
    if wafers:
        ax.add_collection(LineCollection(wafers, colors=wafer_colours, alpha=alpha,
                                         linewidths=linewidth, linestyles='--'))
    ax.autoscale_view()


def plot_roadmap(cell, roadmap, path, max_edges: int = 3000, seed: int = 0) -> Figure:
    """Write a PNG: the cell with the robot at every station, and the roadmap in joint space."""
    fig = Figure(figsize=(15, 6.5))
    ax = fig.add_subplot(1, 2, 1)
    draw_cell(ax, cell)
    palette = colormaps['tab10']
    colours = [palette(i % 10) for i in range(len(cell.stations))]
    for colour, (name, station) in zip(colours, sorted(cell.stations.items())):
        for config in station.configs:
            draw_robot(ax, cell.robot, config.q, colour=colour, alpha=0.8)
            elbow = cell.robot.arm.joint_points(config.q)[1]
            ax.annotate(elbow_words(config.elbow), elbow, xytext=(0, -3),
                        textcoords='offset points', ha='center', va='top', fontsize=6.5,
                        color=colour)
    draw_stations(ax, cell, colours)
    ax.set_title(f'{cell.name}: robot at each station (every elbow branch, named at the '
                 'elbow)', fontsize=11)

    ax3 = fig.add_subplot(1, 2, 2, projection='3d')
    nodes = roadmap.nodes
    rng = np.random.default_rng(seed)
    shown = roadmap.edges[rng.permutation(roadmap.edge_count)[:max_edges]]
    for i, j in shown:
        ax3.plot(*np.stack([nodes[i], nodes[j]]).T, color='0.8', linewidth=0.3)
    for k, name in enumerate(SAMPLER_NAMES):
        mine = nodes[roadmap.sampler == k]
        ax3.scatter(*mine.T, s=3, color=_SAMPLER_COLOURS[k], label=f'{name} ({len(mine)})')
    stations = nodes[roadmap.sampler < 0]
    ax3.scatter(*stations.T, s=40, color='red', marker='*', label='stations')
    for name, set_label in zip(cell.robot.joint_names,
                               (ax3.set_xlabel, ax3.set_ylabel, ax3.set_zlabel)):
        set_label(f'{name} (rad)')
    ax3.set_title(f'roadmap: {roadmap.node_count} nodes, {roadmap.edge_count} edges '
                  f'({min(max_edges, roadmap.edge_count)} drawn)')
    ax3.legend(loc='upper left', fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return fig


def plot_trajectory(cell, result, path, outlines: int = 14) -> Figure:
    """Write a PNG of a plan like the paper's Figs. 10-13: motion, joints, wafer."""
    t = np.linspace(0.0, result.cycle_time, 1500)
    q, qd, qdd, qddd = result.trajectory.evaluate_orders(t, range(4))
    loaded = result.load == LOADED
    ends = motion_label(result.start.label, result.goal.label, result.branches)
    return plot_motion(cell.with_load(result.load), t, q, qd, qdd,
                       f'{ends}{"" if loaded else " (empty)"}: cycle time '
                       f'{result.cycle_time:.3f} s (λ-scaled start '
                       f'{result.initial_cycle_time:.3f} s)', path, outlines, qddd=qddd,
                       curve=result.trajectory)


def plot_cycle(cell, cycle, path, outlines: int = 20) -> Figure:
    """
    Write a PNG of one swap cycle (``service.cycle``): the way out, loaded, then back, empty.

    The figure is ``plot_motion``'s; the wafer limit drawn is the loaded one, which the way
    back (no wafer on the blade, shaded) need not keep.
    """
    out, back = (move.result for move in cycle.moves)
    times, states = [], []
    for offset, result in ((0.0, out.trajectory), (out.cycle_time, back.trajectory)):
        t = np.linspace(0.0, result.duration, 1000)
        times.append(offset + t)
        states.append(result.evaluate_orders(t, range(4)))
    q, qd, qdd, qddd = (np.concatenate([s[k] for s in states]) for k in range(4))
    title = (f'{cycle.loadport} ⇄ {cycle.loadlock}: swap cycle {cycle.cycle:.3f} s per wafer '
             f'(loaded out 0–{out.cycle_time:.3f} s, empty back to {cycle.cycle:.3f} s: no '
             'wafer limit)' + ('' if cycle.stop_and_go is None else
                               f'; stop-and-go {cycle.stop_and_go:.3f} s'))
    return plot_motion(cell, np.concatenate(times), q, qd, qdd, title, path, outlines,
                       qddd=qddd, empty_from=out.cycle_time)


def plot_motion(cell, times, q, qd, qdd, title: str, path, outlines: int = 14,
                dpi: int = 100, qddd=None, curve=None,
                empty_from: Optional[float] = None) -> Figure:
    """
    Write a PNG of a sampled motion like the paper's Figs. 10-13.

    The enclosure with the stations, the robot's outline at ``outlines`` instants coloured
    by time (with a colour bar), the wafer-centre trace and the closest approach to a wall
    or obstacle (the robot then, and the distance); joint position, velocity, acceleration
    and jerk against their limits; the wafer acceleration along x and y against its limit
    (of ``cell``'s limit set in use: an empty move's has none, ``Cell.with_load``; from
    ``empty_from`` s on the motion is empty, shaded, and not held to it).
    ``times`` (N,) s; ``q``, ``qd``, ``qdd`` (N, J) in the robot's joint order; ``qddd`` the
    jerk, or None to difference it from the accelerations (samples of a recording).
    ``curve``: the ``Trajectory`` sampled, on which the closest approach is found as the
    verification finds it; None: on the samples (``trajectory.approach``). ``title`` is
    shown as it is (no mathtext).
    """
    robot = cell.robot
    times = np.asarray(times, float)
    q, qd, qdd = (np.asarray(values, float) for values in (q, qd, qdd))
    jerk_label = 'jerk (rad/s³)'
    if qddd is None:
        qddd = np.gradient(qdd, times, axis=0) if len(times) > 1 else np.zeros_like(qdd)
        jerk_label = 'jerk (rad/s³, from samples)'
    model = cell.clearance_model
    closest = on_curve(model, curve) if curve is not None else on_samples(
        model, times, q, qd, qdd)
    fig = Figure(figsize=(16, 9))
    grid = fig.add_gridspec(4, 3, left=0.05, right=0.985, bottom=0.06, top=0.93,
                            hspace=0.36, wspace=0.2)
    motion = grid[:3, :2].subgridspec(1, 2, width_ratios=(60, 1), wspace=0.14)
    ax = fig.add_subplot(motion[0])
    _draw_motion(ax, cell, times, q, outlines, closest)
    _time_bar(fig.add_subplot(motion[1]), times, ax)
    ax.set_title(_wrapped(title, 120, most=3), parse_math=False)
    _draw_joints(fig, grid, robot, times, (q, qd, qdd, np.asarray(qddd, float)), jerk_label)
    _draw_wafer(fig.add_subplot(grid[3, :2]), robot, times,
                robot.arm.wafer_acceleration(q, qd, qdd), empty_from)
    fig.savefig(path, dpi=dpi)
    return fig


def plot_ends(cell, start, goal, title: str, path, dpi: int = 100) -> Figure:
    """
    Write a PNG of the enclosure with the robot at ``start`` and ``goal`` (None: unknown).

    For a query that has no motion (a refused request); ``title`` (shown as it is, its lines
    wrapped) says why. The stations are marked at their wafer centres. A body of the robot
    that collides (``geometry.contacts``) is filled red, and so is the wall or obstacle it
    collides with; the legend names them.
    """
    fig = Figure(figsize=(11, 7))
    ax = fig.add_axes((0.08, 0.08, 0.9, 0.78))
    draw_cell(ax, cell)
    draw_stations(ax, cell)
    handles = []
    for q, colour, role in ((start, 'tab:blue', 'start'), (goal, 'tab:orange', 'goal')):
        if q is None:
            handles.append(Line2D([], [], linestyle='', label=f'{role}: unknown'))
            continue
        q = np.asarray(q, float)
        draw_robot(ax, cell.robot, q, colour=colour)
        ax.plot(*cell.robot.arm.wafer_center(q), marker='o', color=colour, markersize=5)
        handles.append(Line2D([], [], color=colour, label=f'robot at {role}'))
        for contact in colliding(cell.clearance_model, q):
            _draw_collision(ax, cell, q, contact)
            handles.append(Patch(facecolor=_COLLIDING, alpha=0.45, edgecolor=_COLLIDING,
                                 label=f'{role} collides: {contact.describe()}'))
    ax.legend(handles=handles, loc='best', fontsize=9)
    fig.suptitle(_wrapped(title, 110), parse_math=False, fontsize=11)
    fig.savefig(path, dpi=dpi)
    return fig


def _draw_motion(ax, cell, times, q, outlines: int, closest) -> None:
    robot = cell.robot
    draw_cell(ax, cell)
    draw_stations(ax, cell)
    colours = colormaps['viridis']
    instants = np.linspace(times[0], times[-1], outlines)
    shown = np.column_stack([np.interp(instants, times, q[:, j]) for j in range(q.shape[1])])
    draw_robots(ax, robot, shown, colours(np.linspace(0.0, 1.0, outlines)), alpha=0.55)
    centre = robot.arm.wafer_center(q)
    ax.plot(centre[:, 0], centre[:, 1], color='tab:red', linewidth=2, label='wafer centre')
    ax.plot(*centre[0], marker='o', color=colours(0.0), markersize=8, linestyle='',
            label=f'start (t = {times[0]:.2f} s)')
    ax.plot(*centre[-1], marker='s', color=colours(1.0), markersize=8, linestyle='',
            label=f'goal (t = {times[-1]:.2f} s)')
    _draw_closest(ax, cell, closest)
    drawn = np.vstack([body_outline(robot, config, k) for config in shown for k in range(4)]
                      + [centre])
    ax.legend(loc=_emptiest_corner(ax, drawn), fontsize=9, framealpha=0.9)


def _emptiest_corner(ax, points: np.ndarray) -> str:
    """Return the legend location of the corner of ``ax`` with the fewest ``points``."""
    (left, right), (bottom, top) = ax.get_xlim(), ax.get_ylim()
    x = (points[:, 0] - left) / (right - left)
    y = (points[:, 1] - bottom) / (top - bottom)
    corners = {'upper right': (x > 0.55) & (y > 0.7), 'upper left': (x < 0.45) & (y > 0.7),
               'lower right': (x > 0.55) & (y < 0.3), 'lower left': (x < 0.45) & (y < 0.3)}
    return min(corners, key=lambda corner: int(np.count_nonzero(corners[corner])))


def _time_bar(axis, times, beside) -> None:
    """Draw the colour bar of the outlines' times as tall as ``beside``, scale on the left."""
    beside.apply_aspect()  # the cell's axes shrink to its aspect ratio: match their height
    box, own = beside.get_position(), axis.get_position()
    axis.set_position((own.x0, box.y0, own.width, box.height))
    bar = axis.figure.colorbar(ScalarMappable(Normalize(times[0], times[-1]),
                                              colormaps['viridis']), cax=axis)
    bar.set_label('time of the robot outlines (s)')
    axis.yaxis.set_ticks_position('left')
    axis.yaxis.set_label_position('left')


def _draw_closest(ax, cell, closest: Approach) -> None:
    """Draw the robot at the closest approach, and the gap with its distance."""
    contact = closest.contact
    draw_robot(ax, cell.robot, closest.q, colour=_CLOSEST, linewidth=1.6)
    ax.fill(*body_outline(cell.robot, closest.q, contact.index).T, color=_CLOSEST,
            alpha=0.15)
    near, wall = contact.surface_point(), contact.wall_point
    distance, when = closest.distance * 1000.0, closest.time
    ax.plot(*np.stack([near, wall]).T, color=_CLOSEST, linewidth=2.5, marker='o',
            markersize=3.5, label=f'closest approach: {distance:.1f} mm, {contact.body} vs '
            f'{contact.obstacle}, t = {when:.2f} s')
    inward = np.mean(cell.boundary, axis=0) - wall
    inward = inward / max(float(np.hypot(*inward)), 1e-12)
    ax.annotate(f'{distance:.1f} mm', wall, xytext=tuple(18.0 * inward),
                textcoords='offset points', fontsize=9, fontweight='bold', ha='center',
                va='center', color=_CLOSEST,
                bbox={'facecolor': 'white', 'edgecolor': 'none', 'alpha': 0.8, 'pad': 0.5})


def _draw_collision(ax, cell, q, contact: BodyContact) -> None:
    """Fill a colliding body in red, and the obstacle or the wall it collides with."""
    ax.fill(*body_outline(cell.robot, q, contact.index).T, color=_COLLIDING, alpha=0.45)
    model = cell.clearance_model
    if contact.owner:  # an obstacle: fill it
        ax.add_patch(Polygon(model.polygons[contact.owner], closed=True,
                             facecolor=_COLLIDING, alpha=0.35, edgecolor=_COLLIDING,
                             linewidth=2))
    else:  # the boundary: the wall nearest to the body
        wall = np.stack([model.edge_start[contact.edge], model.edge_end[contact.edge]])
        ax.plot(wall[:, 0], wall[:, 1], color=_COLLIDING, linewidth=4, solid_capstyle='butt')
    ax.plot(*contact.wall_point, marker='X', color=_COLLIDING, markersize=9,
            markeredgecolor='black', linestyle='')


def _draw_joints(fig, grid, robot, times, series, jerk_label: str) -> None:
    lower, upper = robot.limits.position.T
    jerk = robot.limits.jerk
    panels = [('position (rad)', lower, upper),
              ('velocity (rad/s)', -robot.limits.velocity, robot.limits.velocity),
              ('acceleration (rad/s²)', -robot.limits.acceleration, robot.limits.acceleration),
              (jerk_label, None if jerk is None else -jerk, jerk)]
    for row, (values, (label, low, high)) in enumerate(zip(series, panels)):
        axis = fig.add_subplot(grid[row, 2])
        handles = []
        for j, name in enumerate(robot.joint_names):
            line, = axis.plot(times, values[:, j], label=name)
            handles.append(line)
            for bound in () if high is None else (low[j], high[j]):
                axis.axhline(bound, color=line.get_color(), linestyle='--', linewidth=0.8)
        if row and high is None:
            axis.text(0.01, 0.97, f'peak {_peak(np.abs(values)):.0f} rad/s³ (no limit)',
                      transform=axis.transAxes, ha='left', va='top', fontsize=8,
                      bbox={'facecolor': 'white', 'edgecolor': 'none', 'pad': 1.5})
        elif row:
            axis.text(0.01, 0.97, f'peak {_peak(np.abs(values) / high):.1%} of limit',
                      transform=axis.transAxes, ha='left', va='top', fontsize=8,
                      bbox={'facecolor': 'white', 'edgecolor': 'none', 'pad': 1.5})
        else:
            _legend_above(axis, handles)
        axis.set_ylabel(label)
        axis.grid(alpha=0.3)
    axis.set_xlabel('t (s)')


def _draw_wafer(axis, robot, times, wafer, empty_from: Optional[float] = None) -> None:
    handles, limit = [], robot.wafer_limit  # None: an empty move, no wafer limit
    held = times <= (np.inf if empty_from is None else empty_from)  # the limit applies
    for k, name in enumerate('xy'):
        peak = '' if limit is None else \
            f' (peak {_peak(np.abs(wafer[held, k]) / limit.xy[k]):.1%})'
        line, = axis.plot(times, wafer[:, k], label=f'a_{name}{peak}')
        handles.append(line)
        if limit is not None:
            axis.axhline(limit.xy[k], color=line.get_color(), linestyle='--', linewidth=0.8)
            axis.axhline(-limit.xy[k], color=line.get_color(), linestyle='--', linewidth=0.8)
    if limit is not None and limit.norm is not None:
        norm = np.hypot(wafer[:, 0], wafer[:, 1])
        handles += axis.plot(times, norm, color='black',
                             label=f'|a| (peak {_peak(norm[held] / limit.norm):.1%})')
        axis.axhline(limit.norm, color='black', linestyle='--', linewidth=0.8)
    if empty_from is not None:
        axis.axvspan(empty_from, times[-1], color='0.9', zorder=0)
        axis.text(empty_from, 0.97, ' empty: no wafer limit', ha='left', va='top',
                  transform=axis.get_xaxis_transform(), fontsize=8)
    axis.set_ylabel('wafer acceleration (m/s²)' if limit is not None else
                    'blade acceleration (m/s², empty: no limit)')
    axis.set_xlabel('t (s)')
    axis.grid(alpha=0.3)
    _legend_above(axis, handles)


def _legend_above(axis, handles) -> None:
    """Put the legend (the curves, then 'limit') in one row above the axes' right end."""
    limit = Line2D([], [], color='0.3', linestyle='--', linewidth=0.8, label='limit')
    axis.legend(handles=handles + [limit], fontsize=8, ncol=len(handles) + 1,
                loc='lower right', bbox_to_anchor=(1.0, 1.0), frameon=False,
                borderaxespad=0.2)


def _wrapped(title: str, width: int, most: int = 6) -> str:
    """Return ``title`` with each line wrapped to ``width`` characters, ``most`` lines."""
    lines = [part for line in title.split('\n') for part in textwrap.wrap(line, width) or ['']]
    if len(lines) > most:
        lines = lines[:most - 1] + [lines[most - 1][:width - 1] + '…']
    return '\n'.join(lines)


def _peak(ratios: np.ndarray) -> float:
    """Return the largest of ``ratios`` (0 for none)."""
    return float(np.max(ratios)) if np.size(ratios) else 0.0
