import numpy as np
import pytest

from astrobee import rotations as rot
from astrobee_planning.quaternion_poly import QuaternionPolynomial, quat_derivatives, reorientation


def _random_case(seed):
    rng = np.random.default_rng(seed)
    q0, q1 = rot.normalize(rng.normal(size=4)), rot.normalize(rng.normal(size=4))
    w0, a0, w1, a1 = (rng.normal(size=3) * 0.3 for _ in range(4))
    return q0, w0, a0, q1, w1, a1


@pytest.mark.parametrize("seed", range(5))
def test_boundary_conditions_with_nonzero_rates(seed):
    q0, w0, a0, q1, w1, a1 = _random_case(seed)
    p = QuaternionPolynomial.from_boundary(q0, w0, a0, q1, w1, a1, 6.0, t0=3.0)
    q, w, a = p.evaluate([3.0, 9.0])
    assert abs(abs(q[0] @ q0) - 1) < 1e-12 and abs(abs(q[1] @ q1) - 1) < 1e-12
    np.testing.assert_allclose(w, [w0, w1], atol=1e-10)
    np.testing.assert_allclose(a, [a0, a1], atol=1e-10)


@pytest.mark.parametrize("seed", range(3))
def test_rates_match_finite_differences(seed):
    """w and alpha against central differences with steps where truncation and rounding are both
    far below the tolerance (a second difference at h=1e-5 is rounding noise of ~2e-4)."""
    q0, w0, a0, q1, w1, a1 = _random_case(seed)
    p = QuaternionPolynomial.from_boundary(q0, w0, a0, q1, w1, a1, 5.0)
    h1, h2 = 1e-5, 1e-3           # first difference: rounding ~1e-11; second: truncation ~1e-7
    for t in (0.0 + 2 * h2, 1.3, 2.5, 4.9, 5.0 - 2 * h2):
        qm, qc, qp = (p.evaluate([t + d])[0][0] for d in (-h1, 0.0, h1))
        w_fd = 2 * rot.multiply((qp - qm) / (2 * h1), rot.conjugate(qc))[:3]
        _, w, a = p.evaluate([t])
        np.testing.assert_allclose(w[0], w_fd, atol=1e-7)
        # alpha from the second difference of q: vec(2 q'' q*) (q' q'* is scalar)
        qm, qp = (p.evaluate([t + d])[0][0] for d in (-h2, h2))
        a_fd = 2 * rot.multiply((qp - 2 * qc + qm) / h2**2, rot.conjugate(qc))[:3]
        np.testing.assert_allclose(a[0], a_fd, atol=1e-5)
        # and from the first difference of the analytic w
        _, (wm, wp), _ = p.evaluate([t - h2, t + h2])
        np.testing.assert_allclose(a[0], (wp - wm) / (2 * h2), atol=1e-5)
    # the end values by one-sided differences of w
    _, w_end, _ = p.evaluate([5.0 - 1e-4, 5.0])
    assert np.allclose((w_end[1] - w_end[0]) / 1e-4, a1, atol=1e-3)


def test_second_derivative_has_scalar_term():
    """q_ddot = 0.5 [alpha,0] q - |w|^2/4 q: q . q_ddot = -|w|^2/4 (unit norm kept to 2nd order)."""
    q0, w0, a0, *_ = _random_case(7)
    qd, qdd = quat_derivatives(q0, w0, a0)
    assert abs(q0 @ qd) < 1e-14
    assert abs(q0 @ qdd + (w0 @ w0) / 4) < 1e-14
    # d^2/dt^2 |q|^2 = 2 (|qd|^2 + q.qdd) = 0
    assert abs(qd @ qd + q0 @ qdd) < 1e-14


def test_reorientation_within_limits_and_reaches_goal():
    q0 = rot.IDENTITY
    q1 = rot.from_euler(0.3, -0.4, 2.5)
    p = reorientation(q0, q1, 0.1745, 0.1745)
    wm, am = p.peak_rates(1000)
    assert wm <= 0.1745 and am <= 0.1745
    q, w, a = p.evaluate([p.duration])
    assert rot.angle_between(q[0], q1) < 1e-9
    assert np.allclose(w, 0) and np.allclose(a, 0)


def test_batched_transport_and_peak_rates_match_the_one_by_one_forms():
    """attitude.transported_headings (prefix scan) equals the step-by-step parallel transport,
    including a half turn; peak_rates_batch equals the max of each piece's peak_rates."""
    from astrobee_planning import attitude
    from astrobee_planning.quaternion_poly import peak_rates_batch
    rng = np.random.default_rng(4)
    u = np.cumsum(rng.normal(size=(300, 3)) * 0.05, axis=0) + [1.0, 0, 0]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u[7] = -u[6]
    q = [attitude.heading_from_direction(u[0])]
    for k in range(1, len(u)):
        q.append(rot.normalize(rot.multiply(attitude.min_rotation(u[k - 1], u[k]), q[-1])))
    np.testing.assert_allclose(attitude.transported_headings(q[0], u), np.array(q), atol=1e-12)
    polys = [QuaternionPolynomial.from_boundary(rot.normalize(rng.normal(size=4)), rng.normal(size=3) * 0.1,
                                                rng.normal(size=3) * 0.01, rot.normalize(rng.normal(size=4)),
                                                rng.normal(size=3) * 0.1, rng.normal(size=3) * 0.01, 3.0 + i)
             for i in range(5)]
    one = (max(p.peak_rates(150)[0] for p in polys), max(p.peak_rates(150)[1] for p in polys))
    np.testing.assert_allclose(peak_rates_batch(polys, 150), one, rtol=1e-12)
