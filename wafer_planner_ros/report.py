"""Plain-data (JSON) form of plan results and errors, shared by the tools."""

import numpy as np

from wafer_planner_ros.cell.limits import LOADED


def plan_json(result, roadmap_info: dict, joint_names) -> dict:
    """Return a successful plan as the tools' JSON object (doc/operations.md, the tools)."""
    points = [{'t': float(t), 'q': q.tolist(), 'qd': qd.tolist(), 'qdd': qdd.tolist()}
              for t, q, qd, qdd in zip(result.times, result.positions, result.velocities,
                                       result.accelerations)]
    return {
        'status': 'ok', 'code': 'OK',
        'message': '; '.join(result.warnings) or 'ok',
        'from': result.start.label, 'to': result.goal.label, 'load': result.load,
        'joint_names': list(joint_names),
        'cycle_time': result.cycle_time,
        'initial_cycle_time': result.initial_cycle_time,
        'spline': result.trajectory.describe(),
        'points': points,
        'path': result.path.tolist(),
        'roadmap_path': result.roadmap_path.tolist(),
        'metrics': _plain(measured(result)),
        'timings_ms': _plain(result.timings_ms),
        'roadmap': roadmap_info,
    }


def measured(result) -> dict:
    """Return what was measured of a plan: the verification's figures and the metrics."""
    checked, proof = result.verification, result.verification.proof
    return dict(result.metrics, min_clearance=checked.min_clearance,
                limit_ratios=dict(checked.ratios), peak_jerk=list(checked.peak_jerk),
                peak_wafer_jerk=checked.peak_wafer_jerk,
                limit_checks=checked.limit_samples, collision_checks=checked.collision_samples,
                certified=proof.certified, proof_pieces=proof.pieces, proof_depth=proof.depth,
                proof_evaluations=proof.evaluations)


def error_json(code: str, message: str, start, goal, roadmap_info: dict,
               load: str = LOADED) -> dict:
    """Return a failed request as the tools' JSON object (doc/operations.md, the tools)."""
    return {'status': 'error', 'code': code, 'message': message, 'from': _label(start),
            'to': _label(goal), 'load': load, 'roadmap': roadmap_info}


def roadmap_json(cached) -> dict:
    """Return the roadmap block of the JSON object."""
    roadmap = cached.roadmap
    return {'nodes': roadmap.node_count, 'edges': roadmap.edge_count, 'hash': roadmap.digest,
            'seed': roadmap.seed, 'cache_hit': cached.hit}


def _label(value) -> str:
    if isinstance(value, str):
        return value
    return ','.join(f'{v:g}' for v in np.asarray(value, float).reshape(-1))


def _plain(value):
    """Return value with numpy scalars and arrays turned into JSON types."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value
