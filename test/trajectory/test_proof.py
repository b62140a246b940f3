"""The proof that a curve is collision-free: sound against dense sampling, and it refutes."""

import numpy as np
import pytest

from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.planner import Planner
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.proof import prove
from wafer_planner_ros.trajectory.verify import COLLISION_STEP, collision_times, verify

DENSE = 200001
"""Samples of the dense clearance check the proof is compared with."""
GRAZING_SAMPLES = 50001
"""Samples that find a curve's closest approach to a wall."""


def _curve(points, duration: float = 1.0) -> CubicBSpline:
    """Return a clamped cubic through rest at both ends with uniform spans."""
    points = np.asarray(points, float)
    points = np.vstack([points[:1], points[:1], points, points[-1:], points[-1:]])
    spans = len(points) - 3
    return CubicBSpline.from_intervals(points, np.full(spans, duration / spans))


def _dense_clearance(cell, curve) -> np.ndarray:
    return cell.clearance_model.clearance(curve.evaluate(np.linspace(0.0, curve.duration,
                                                                     DENSE)))


def test_peak_speed_is_exact_on_any_interval_within_a_span():
    rng = np.random.default_rng(3)
    curve = _curve(rng.uniform(-1.0, 1.0, (6, 3)), duration=2.0)
    breaks = curve.breaks()
    span = rng.integers(0, len(breaks) - 1, 300)
    ends = np.sort(rng.uniform(breaks[span, None], breaks[span + 1, None], (300, 2)), axis=1)
    peaks = curve.peak_speed(ends[:, 0], ends[:, 1])
    for (a, b), peak in zip(ends, peaks):
        sampled = np.abs(curve.evaluate(np.linspace(a, b, 2001), 1)).max(axis=0)
        assert np.all(sampled <= peak + 1e-12)
        assert np.allclose(sampled, peak, rtol=1e-5, atol=1e-9)


def test_every_planned_curve_of_every_cell_is_proven(cell, roadmap):
    planner = Planner(cell, roadmap)
    for start, goal in station_pairs(cell):
        result = planner.plan(start, goal)
        proof = result.verification.proof
        assert proof.certified and proof.collision is None and len(proof.unproven) == 0
        assert proof.pieces >= len(result.trajectory.breaks()) - 1
        assert proof.evaluations == proof.pieces + 1  # each split adds one middle


def test_a_curve_through_a_wall_is_refuted_where_it_collides(default_cell):
    station = default_cell.stations
    qa, qb = station['loadport1'].configs[0].q, station['loadlock1'].configs[0].q
    wall = np.array([-np.pi / 2, 0.0, 0.0])  # the arm stretched through the back wall
    assert default_cell.clearance_model.clearance(wall[None])[0] <= 0.0
    curve = _curve([qa, wall, qb])
    proof = prove(curve, default_cell.clearance_model, default_cell.robot.lipschitz)
    assert not proof.certified and proof.collision is not None
    assert default_cell.clearance_model.clearance(curve.evaluate([proof.collision]))[0] <= 0.0
    a, b = proof.unproven[0]
    assert a <= proof.collision <= b


@pytest.mark.slow
def test_the_proof_is_sound_and_decides_clear_cases(default_cell):
    """Random curves near free configurations: proven ones are free at every sample."""
    model, lipschitz = default_cell.clearance_model, default_cell.robot.lipschitz
    rng = np.random.default_rng(11)
    lower, upper = default_cell.robot.limits.position.T
    centres = rng.uniform(lower, upper, (4000, 3))
    centres = centres[model.clearance(centres) > 0.0][:100]
    certified = refuted = 0
    for centre in centres:
        points = centre + rng.normal(0.0, 0.15, (4, 3))
        curve = _curve(points, duration=rng.uniform(0.5, 3.0))
        dense = _dense_clearance(default_cell, curve).min()
        proof = prove(curve, model, lipschitz)
        if proof.certified:
            certified += 1
            assert dense > 0.0, 'a curve proven free collides between samples'
        if dense <= 0.0:
            refuted += 1
            assert not proof.certified
        if dense > 1e-3:  # clear by a millimetre: the bisection must get there
            assert proof.certified
    assert certified >= 10 and refuted >= 10  # both kinds were really tried


@pytest.mark.slow
def test_curves_grazing_a_wall_are_told_apart_at_a_fifth_of_a_millimetre(default_cell):
    """
    A curve that dips 0.2 mm into a wall for a moment is refuted; one 0.2 mm clear, proven.

    Random excursions from free configurations are scaled until their closest approach is
    -0.2 mm or +0.2 mm (dense sampling): a proof with too small Lipschitz constants, or
    one that trusted its middles alone, would certify the first kind.
    """
    model, lipschitz = default_cell.clearance_model, default_cell.robot.lipschitz
    rng = np.random.default_rng(5)
    lower, upper = default_cell.robot.limits.position.T
    centres = rng.uniform(lower, upper, (4000, 3))
    centres = centres[model.clearance(centres) > 0.01]
    tried = 0
    for centre in centres:
        excursion = rng.normal(0.0, 0.4, (4, 3))
        samples = np.linspace(0.0, 1.0, GRAZING_SAMPLES)

        def closest(scale):
            curve = _curve(np.vstack([centre, centre + scale * excursion, centre]))
            return curve, model.clearance(curve.evaluate(samples)).min()

        if closest(1.0)[1] > -0.001:
            continue
        for target, certified in ((-2e-4, False), (2e-4, True)):
            low, high = 0.0, 1.0  # closest(low) > target >= closest(high)
            for _ in range(24):
                middle = 0.5 * (low + high)
                low, high = (middle, high) if closest(middle)[1] > target else (low, middle)
            curve, distance = closest(low if certified else high)
            assert abs(distance - target) < 1e-4
            assert prove(curve, model, lipschitz).certified is certified
        tried += 1
        if tried == 8:
            break
    assert tried == 8


def test_a_curve_not_clamped_at_zero_is_proven_and_checked_over_all_its_time(
        default_cell, default_roadmap):
    """
    Knots shifted by 0.3 s: evaluated from t = 0, each curve first runs backwards.

    Its polynomial pieces begin at 0.3 s; the proof and the dense check cover [0, T] all the
    same, so a curve through the wall before its first piece is refuted and caught.
    """
    planner = Planner(default_cell, default_roadmap)
    model, lipschitz = default_cell.clearance_model, default_cell.robot.lipschitz
    curves = [planner.plan(start, goal).trajectory for start, goal in station_pairs(default_cell)]
    refuted = 0
    for curve in curves:
        shifted = CubicBSpline(curve.knots + 0.3, curve.control_points)
        assert shifted.breaks()[0] == pytest.approx(0.3)
        proof = prove(shifted, model, lipschitz)
        if _dense_clearance(default_cell, shifted).min() <= 0.0:
            refuted += 1
            assert not proof.certified
    assert refuted >= 1
    for curve in curves:
        shifted = CubicBSpline(curve.knots + 0.3, curve.control_points)
        times = collision_times(shifted)
        assert times[0] == 0.0 and times[-1] == shifted.duration
        assert np.abs(np.diff(shifted.evaluate(times), axis=0)).max() <= COLLISION_STEP * (
            1.0 + 1e-9)
        assert not verify(shifted, default_cell, curve.control_points[0],
                          curve.control_points[-1]).ok
