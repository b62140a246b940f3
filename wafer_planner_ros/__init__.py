"""Wafer-transfer robot planner: PRM roadmap, certified edges, B-spline trajectories."""

__version__ = '0.1.0'
