import numpy as np
import pytest

from astrobee import rotations as rot
from astrobee_planning import local_planner


def _state(rng):
    return {"pos": rng.normal(size=3), "vel": rng.normal(size=3) * 0.1, "acc": rng.normal(size=3) * 0.01,
            "quat": rot.normalize(rng.normal(size=4)), "omega": rng.normal(size=3) * 0.1,
            "alpha": rng.normal(size=3) * 0.05}


@pytest.mark.parametrize("seed", range(4))
def test_hits_boundary_states_exactly(seed):
    rng = np.random.default_rng(seed)
    a, b = _state(rng), _state(rng)
    tr = local_planner.plan(a, b, 4.0)
    st = tr.sample([0.0, 4.0])
    for i, s in enumerate((a, b)):
        np.testing.assert_allclose(st.pos[i], s["pos"], atol=1e-12)
        np.testing.assert_allclose(st.vel[i], s["vel"], atol=1e-12)
        np.testing.assert_allclose(st.acc[i], s["acc"], atol=1e-12)
        assert abs(abs(st.quat[i] @ s["quat"]) - 1) < 1e-12
        np.testing.assert_allclose(st.omega[i], s["omega"], atol=1e-10)
        np.testing.assert_allclose(st.alpha[i], s["alpha"], atol=1e-10)


def test_batch_matches_single():
    rng = np.random.default_rng(11)
    starts = [_state(rng) for _ in range(6)]
    goals = [_state(rng) for _ in range(6)]
    T = rng.uniform(1, 5, size=6)
    cols = lambda ss, k: np.array([s[k] for s in ss])  # noqa: E731
    keys = ("pos", "vel", "acc", "quat", "omega", "alpha")
    pts, coef = local_planner.plan_batch(*(cols(starts, k) for k in keys), *(cols(goals, k) for k in keys), T)
    s = np.linspace(0, 1, 7)
    pos, vel, acc, q = local_planner.evaluate_batch(pts, coef, T, s)
    for i in range(6):
        tr = local_planner.plan(starts[i], goals[i], T[i])
        st = tr.sample(s * T[i])
        np.testing.assert_allclose(pos[i], st.pos, atol=1e-12)
        np.testing.assert_allclose(vel[i], st.vel, atol=1e-12)
        np.testing.assert_allclose(acc[i], st.acc, atol=1e-12)
        np.testing.assert_allclose(np.abs(np.sum(q[i] * st.quat, axis=1)), 1.0, atol=1e-12)


def test_is_minimum_jerk_quintic():
    """Rest-to-rest: the quintic 10s^3-15s^4+6s^5 profile."""
    z = np.zeros(3)
    a = {"pos": z, "vel": z, "acc": z, "quat": rot.IDENTITY, "omega": z, "alpha": z}
    b = dict(a, pos=np.array([1.0, 0, 0]))
    tr = local_planner.plan(a, b, 2.0)
    s = np.linspace(0, 1, 11)
    np.testing.assert_allclose(tr.sample(2 * s).pos[:, 0], 10 * s**3 - 15 * s**4 + 6 * s**5, atol=1e-12)


def test_bad_input():
    z = np.zeros(3)
    a = {"pos": z, "vel": z, "acc": z, "quat": rot.IDENTITY, "omega": z, "alpha": z}
    with pytest.raises(ValueError):
        local_planner.plan(a, dict(a, pos=np.array([np.nan, 0, 0])), 1.0)
    with pytest.raises(ValueError):
        local_planner.plan(a, dict(a, quat=np.array([0, 0, 0, 2.0])), 1.0)
    with pytest.raises(ValueError):
        local_planner.plan(a, a, 0.0)
