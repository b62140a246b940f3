"""Certified edges: never through an obstacle, and not needlessly refused."""

from dense_check import colliding_segments, segment_points
import numpy as np

from wafer_planner_ros.geometry.certify import certify_segments


def _free(cell, n, rng):
    limits = cell.robot.limits.position
    q = rng.uniform(limits[:, 0], limits[:, 1], (4 * n, 3))
    return q[cell.clearance_model.clearance(q) > 0][:n]


def test_certified_segments_are_collision_free_when_checked_densely_with_fcl(cell):
    rng = np.random.default_rng(31)
    model = cell.clearance_model
    qa = _free(cell, 400, rng)
    qb = np.clip(qa + rng.normal(0, 0.4, qa.shape), *cell.robot.limits.position.T)
    keep = model.clearance(qb) > 0
    qa, qb = qa[keep], qb[keep]
    ok, evaluations = certify_segments(model, cell.robot.lipschitz, qa, qb,
                                       model.body_clearance(qa), model.body_clearance(qb))
    colliding = colliding_segments(cell.fcl_model(), qa, qb)
    assert not np.any(ok[colliding]), 'a certified segment collides'
    # Both outcomes occur, so the check means something.
    assert 0 < len(colliding) and ok.sum() > len(qa) // 4
    assert evaluations > 0
    # Refused segments that fcl finds free are rare: the certificate is not needlessly tight.
    refused_free = np.setdiff1d(np.nonzero(~ok)[0], colliding)
    assert len(refused_free) <= 0.02 * len(qa)


def test_straight_lines_between_loadports_and_loadlocks_collide_and_are_refused(
        default_cell):
    # On the default cell every such line collides, so the roadmap is needed.
    model, stations = default_cell.clearance_model, default_cell.stations
    qa, qb = [], []
    for port in ('loadport1', 'loadport2', 'loadport3'):
        for lock in ('loadlock1', 'loadlock2'):
            for a in stations[port].configs:
                for b in stations[lock].configs:
                    qa.append(a.q)
                    qb.append(b.q)
    qa, qb = np.array(qa), np.array(qb)
    assert len(colliding_segments(default_cell.fcl_model(), qa, qb)) == len(qa) == 24
    ok, _ = certify_segments(model, default_cell.robot.lipschitz, qa, qb,
                             model.body_clearance(qa), model.body_clearance(qb))
    assert not ok.any()


def test_dense_points_respect_the_step():
    qa = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    qb = np.array([[0.01, -0.0045, 0.0], [1.0, 1.0, 1.0]])
    owner, q = next(segment_points(qa, qb))
    first = q[owner == 0]
    assert np.allclose(first[0], qa[0]) and np.allclose(first[-1], qb[0])
    assert np.abs(np.diff(first, axis=0)).max() <= 1e-3 + 1e-15
    assert (owner == 1).sum() == 2


class _Touching:
    """A body whose clearance is 0.195 (q1 + pi/2)^2 m: a link that just reaches a wall."""

    def body_clearance(self, q):
        q = np.atleast_2d(q)
        return 0.195 * (q[:, :1] + np.pi / 2) ** 2


def test_a_segment_that_touches_an_obstacle_at_one_point_is_refused_at_once():
    # A study's variant whose shoulder link reached a wall exactly (0.39 m + 0.06 m of
    # radius, the wall 0.45 m away) took five minutes to build its roadmap: each edge across
    # the touching angle was refused only when a midpoint hit it to the last bit, and the
    # pieces near it stayed open, doubling every other level.
    model, lipschitz = _Touching(), np.array([[0.45, 0.0, 0.0]])
    qa = np.array([[-np.pi / 2 - 0.3 - 0.01 * k, 0.2, 0.1] for k in range(20)])
    qb = np.array([[-np.pi / 2 + 0.2 + 0.013 * k, -0.4, 0.3] for k in range(20)])
    ok, evaluations = certify_segments(model, lipschitz, qa, qb, model.body_clearance(qa),
                                       model.body_clearance(qb))
    assert not ok.any()
    assert evaluations < 20 * 2000
    # Away from the touching angle the same segments' halves are certified.
    ok, _ = certify_segments(model, lipschitz, qa, qa + 0.2, model.body_clearance(qa),
                             model.body_clearance(qa + 0.2))
    assert ok.all()
