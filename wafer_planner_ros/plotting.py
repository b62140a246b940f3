"""Figures: the enclosure with the robot, and the roadmap in joint space (paper Figs. 4-5)."""

import matplotlib

matplotlib.use('Agg')

import matplotlib.pyplot as plt  # noqa: E402, I100 - the backend must be chosen first
import numpy as np  # noqa: E402

from wafer_planner_ros.roadmap import SAMPLER_NAMES  # noqa: E402

_SAMPLER_COLOURS = ('tab:blue', 'tab:orange', 'tab:green')


def capsule_outline(a: np.ndarray, b: np.ndarray, radius: float, n: int = 16) -> np.ndarray:
    """Return the outline (K, 2) of the capsule swept by ``radius`` along a-b."""
    heading = np.arctan2(*(b - a)[::-1]) if np.any(b != a) else 0.0
    arc = np.linspace(-np.pi / 2, np.pi / 2, n)
    end = b + radius * np.column_stack([np.cos(heading + arc), np.sin(heading + arc)])
    start = a + radius * np.column_stack([np.cos(heading + np.pi + arc),
                                          np.sin(heading + np.pi + arc)])
    return np.vstack([end, start, end[:1]])


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


def draw_robot(ax, robot, q: np.ndarray, colour='tab:blue', alpha=1.0, wafer=True) -> None:
    """Draw the link capsules and the wafer of the robot at configuration q."""
    points = robot.arm.joint_points(np.asarray(q, float))
    for k in range(3):
        outline = capsule_outline(points[k], points[k + 1], robot.link_radii[k])
        ax.plot(outline[:, 0], outline[:, 1], color=colour, alpha=alpha, linewidth=1)
    if wafer:
        angle = np.linspace(0.0, 2.0 * np.pi, 64)
        centre = points[3]
        ax.plot(centre[0] + robot.wafer_radius * np.cos(angle),
                centre[1] + robot.wafer_radius * np.sin(angle),
                color=colour, alpha=alpha, linewidth=1, linestyle='--')


def plot_roadmap(cell, roadmap, path, max_edges: int = 3000, seed: int = 0) -> None:
    """Write a PNG: the cell with the robot at every station, and the roadmap in joint space."""
    fig = plt.figure(figsize=(15, 6.5))
    ax = fig.add_subplot(1, 2, 1)
    draw_cell(ax, cell)
    colours = plt.get_cmap('tab10')
    for i, (name, station) in enumerate(sorted(cell.stations.items())):
        for config in station.configs:
            draw_robot(ax, cell.robot, config.q, colour=colours(i % 10), alpha=0.8)
        centre = cell.robot.arm.wafer_center(station.configs[0].q)
        ax.annotate(name, centre, ha='center', va='center', fontsize=8)
    ax.set_title(f'{cell.name}: robot at each station (every elbow branch)')

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
    ax3.set_xlabel('q1 (rad)')
    ax3.set_ylabel('q2 (rad)')
    ax3.set_zlabel('q3 (rad)')
    ax3.set_title(f'roadmap: {roadmap.node_count} nodes, {roadmap.edge_count} edges '
                  f'({min(max_edges, roadmap.edge_count)} drawn)')
    ax3.legend(loc='upper left', fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_trajectory(cell, result, path, outlines: int = 14) -> None:
    """Write a PNG of a plan like the paper's Figs. 10-13: motion, joints, wafer."""
    robot, spline = cell.robot, result.spline
    t = np.linspace(0.0, spline.duration, 1500)
    q, qd, qdd = spline.evaluate_orders(t)
    wafer = robot.arm.wafer_acceleration(q, qd, qdd)
    fig = plt.figure(figsize=(16, 9))
    grid = fig.add_gridspec(3, 3)
    ax = fig.add_subplot(grid[:2, :2])
    draw_cell(ax, cell)
    colours = plt.get_cmap('viridis')
    for k, tk in enumerate(np.linspace(0.0, spline.duration, outlines)):
        draw_robot(ax, robot, spline.evaluate(tk)[0], colour=colours(k / (outlines - 1)),
                   alpha=0.55)
    centre = robot.arm.wafer_center(q)
    ax.plot(centre[:, 0], centre[:, 1], color='tab:red', linewidth=2, label='wafer centre')
    ax.legend(loc='upper right')
    ax.set_title(f'{result.start.label} -> {result.goal.label}: cycle time '
                 f'{result.cycle_time:.3f} s (λ-scaled {result.initial_cycle_time:.3f} s), '
                 f'branches {list(result.branches)}')
    panels = [(grid[0, 2], q, None, 'position (rad)'),
              (grid[1, 2], qd, robot.limits.velocity, 'velocity (rad/s)'),
              (grid[2, 2], qdd, robot.limits.acceleration, 'acceleration (rad/s²)')]
    for spec, values, limit, label in panels:
        axis = fig.add_subplot(spec)
        for j, name in enumerate(robot.joint_names):
            line, = axis.plot(t, values[:, j], label=name)
            if limit is not None:
                axis.axhline(limit[j], color=line.get_color(), linestyle='--', linewidth=0.8)
                axis.axhline(-limit[j], color=line.get_color(), linestyle='--', linewidth=0.8)
        axis.set_ylabel(label)
        axis.legend(fontsize=7, loc='upper right')
    axis.set_xlabel('t (s)')
    wafer_axis = fig.add_subplot(grid[2, :2])
    for k, name in enumerate('xy'):
        line, = wafer_axis.plot(t, wafer[:, k], label=f'a_{name}')
        limit = robot.wafer_acceleration_limit[k]
        wafer_axis.axhline(limit, color=line.get_color(), linestyle='--', linewidth=0.8)
        wafer_axis.axhline(-limit, color=line.get_color(), linestyle='--', linewidth=0.8)
    if robot.wafer_acceleration_norm_limit is not None:
        wafer_axis.plot(t, np.hypot(wafer[:, 0], wafer[:, 1]), color='black', label='|a|')
        wafer_axis.axhline(robot.wafer_acceleration_norm_limit, color='black', linestyle='--',
                           linewidth=0.8)
    wafer_axis.set_ylabel('wafer acceleration (m/s²)')
    wafer_axis.set_xlabel('t (s)')
    wafer_axis.legend(fontsize=8, loc='upper right')
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
