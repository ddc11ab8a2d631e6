"""The wrench allocation (astrobee_control.allocation) against brute force: a dense grid over
the body force with, for each force, the exact best torque (the torque rows are separable: the
per-axis clip of tau_des + c x F)."""
import numpy as np
import pytest

from astrobee import flight_modes
from astrobee_control import allocation as al

FM = flight_modes.get("nominal")
F_LIM, T_LIM = np.asarray(FM.max_force, float), np.asarray(FM.max_torque, float)
LEVER = np.array([-0.25, 0.0, -0.03])   # robot -> pair centre, a 10 kg bag behind the robot


def brute_force(f_des, tau_des, lever, n=81, w_f=1.0, w_t=30.0, around=None, span=None):
    """Lowest objective over an n^3 grid of forces (whole box, or `span` around `around`)."""
    axes = [np.linspace(-F_LIM[i], F_LIM[i], n) if around is None else
            np.clip(np.linspace(around[i] - span[i], around[i] + span[i], n), -F_LIM[i], F_LIM[i])
            for i in range(3)]
    F = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    tau = np.clip(tau_des + np.cross(lever, F), -T_LIM, T_LIM)
    r_f = w_f * (F - f_des) / F_LIM
    r_t = w_t * (tau - np.cross(lever, F) - tau_des) / T_LIM
    c = np.sum(r_f ** 2, 1) + np.sum(r_t ** 2, 1)
    i = int(np.argmin(c))
    return F[i], tau[i], float(c[i])


@pytest.mark.parametrize("solve", [al.allocate, al.guard])
def test_unsaturated_is_exact(solve):
    """Nothing saturates: the wanted force whole, its torque about the centre cancelled (the
    least squares and the guard alike)."""
    f_des, tau_des = np.array([0.1, -0.05, 0.02]), np.array([0.001, -0.002, 0.003])
    F, tau = solve(f_des, tau_des, LEVER, F_LIM, T_LIM)
    np.testing.assert_allclose(F, f_des, atol=1e-12)
    np.testing.assert_allclose(tau - np.cross(LEVER, F), tau_des, atol=1e-12)


@pytest.mark.parametrize("seed", range(12))
def test_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    # wanted wrenches up to 3x the limits: most cases saturate some axes
    f_des = rng.uniform(-3, 3, 3) * F_LIM
    tau_des = rng.uniform(-3, 3, 3) * T_LIM
    lever = LEVER + rng.normal(0, 0.05, 3)
    F, tau = al.allocate(f_des, tau_des, lever, F_LIM, T_LIM)
    assert np.all(np.abs(F) <= F_LIM + 1e-12) and np.all(np.abs(tau) <= T_LIM + 1e-12)
    got = al.cost(F, tau, f_des, tau_des, lever, F_LIM, T_LIM)
    Fg, _, coarse = brute_force(f_des, tau_des, lever)
    # refine the grid around the coarse optimum (cell size / 40)
    _, _, fine = brute_force(f_des, tau_des, lever, 81, around=Fg, span=2 * F_LIM / 80)
    assert got <= min(coarse, fine) + 1e-9
    assert got >= fine - 1e-2 * (1 + fine)   # and the grid gets as low (sanity of the check)


def test_attitude_first_uses_force_for_torque():
    """A wanted pitch torque beyond the torque limit: the allocation gives up force tracking and
    tilts the force so that -c x F adds the missing torque about the pair's centre."""
    tau_des = np.array([0.0, 2.0 * T_LIM[1], 0.0])
    F, tau = al.allocate(np.zeros(3), tau_des, LEVER, F_LIM, T_LIM)
    about_centre = tau - np.cross(LEVER, F)
    assert abs(tau[1]) == pytest.approx(T_LIM[1])
    assert about_centre[1] > 1.5 * T_LIM[1]


def test_scipy_fallback_agrees():
    from scipy.optimize import lsq_linear
    rng = np.random.default_rng(7)
    for _ in range(20):
        A, b = al.problem(rng.uniform(-3, 3, 3) * F_LIM, rng.uniform(-3, 3, 3) * T_LIM, LEVER,
                          F_LIM, T_LIM, 1.0, 30.0)
        x = al.box_lsq(A, b)
        ref = lsq_linear(A, b, bounds=(-np.ones(6), np.ones(6)), method="bvls").x
        assert np.sum((A @ x - b) ** 2) <= np.sum((A @ ref - b) ** 2) + 1e-9


@pytest.mark.parametrize("seed", range(12))
def test_guard_never_opposes_a_saturated_attitude(seed):
    """Wanted wrenches up to 3x the limits: on every axis whose wanted torque the body torque
    cannot meet, the torque about the pair's centre (tau - c x F) is at least the limit in the
    wanted direction (the force does not take from it); the kept share of the cross-lever force
    is the largest such (brute force over the share); the along-lever part is never cut unless
    the box asks; both within the limits."""
    rng = np.random.default_rng(100 + seed)
    f_des = rng.uniform(-3, 3, 3) * F_LIM
    tau_des = rng.uniform(-3, 3, 3) * T_LIM
    lever = LEVER + rng.normal(0, 0.05, 3)
    F, tau = al.guard(f_des, tau_des, lever, F_LIM, T_LIM)
    assert np.all(np.abs(F) <= F_LIM + 1e-12) and np.all(np.abs(tau) <= T_LIM + 1e-12)
    about = tau - np.cross(lever, F)
    sat = np.abs(tau_des) >= T_LIM
    assert np.all(about[sat] * np.sign(tau_des[sat]) >= T_LIM[sat] - 1e-12)
    # brute force: the largest share s of the clipped force's cross-lever part that keeps
    # |tau_des + c x F(s)| within max(limit, |tau_des|) on every axis
    Fc = np.clip(f_des, -F_LIM, F_LIM)
    u = lever / np.linalg.norm(lever)
    par = (Fc @ u) * u
    bound = np.maximum(T_LIM, np.abs(tau_des))
    shares = np.linspace(0.0, 1.0, 100001)
    cand = par[None, :] + shares[:, None] * (Fc - par)[None, :]
    ok = np.all(np.abs(tau_des[None, :] + np.cross(lever[None, :], cand)) <= bound + 1e-12, 1)
    best = cand[np.flatnonzero(ok).max()]
    best = best * min(1.0, float(np.min(F_LIM / np.maximum(np.abs(best), 1e-300))))
    np.testing.assert_allclose(F, best, atol=2e-5 * F_LIM.max())


def test_guard_does_not_bend_the_force_for_torque():
    """A wanted pitch torque beyond the limit and no wanted force: where allocate tilts the
    force to make torque (the route traded for attitude), the guard asks no force at all."""
    tau_des = np.array([0.0, 2.0 * T_LIM[1], 0.0])
    F, tau = al.guard(np.zeros(3), tau_des, LEVER, F_LIM, T_LIM)
    np.testing.assert_allclose(F, 0.0, atol=1e-15)
    assert tau[1] == pytest.approx(T_LIM[1])


@pytest.mark.parametrize("seed", range(20))
def test_keep_along_never_pushes_ahead_of_the_route(seed):
    """keep_along on allocate's wrench for random wanted wrenches and route directions:
    brake_only leaves the force along the route at most the wanted (boxed) force's and, where
    allocate pushed no further than that, the wrench untouched; route mode puts it back to the
    wanted one up to the box; the across-route part is allocate's (up to the box); the torque
    is the exact best for the kept force."""
    rng = np.random.default_rng(seed)
    f_des = rng.uniform(-1.5, 1.5, 3) * F_LIM
    tau_des = rng.uniform(-4, 4, 3) * T_LIM
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    F0, tau0 = al.allocate(f_des, tau_des, LEVER, F_LIM, T_LIM, 1.0, 3.0)
    want = float(np.clip(f_des, -F_LIM, F_LIM) @ u)
    F, tau = al.keep_along(F0, tau0, f_des, u, tau_des, LEVER, F_LIM, T_LIM, brake_only=True)
    assert np.all(np.abs(F) <= F_LIM + 1e-12)
    if F0 @ u <= want:
        np.testing.assert_array_equal(F, F0)
        np.testing.assert_array_equal(tau, tau0)
    else:
        assert F @ u <= want + 1e-9 or np.any(np.abs(np.abs(F) - F_LIM) < 1e-12)
        assert F @ u < F0 @ u
        np.testing.assert_allclose(tau, np.clip(tau_des + np.cross(LEVER, F), -T_LIM, T_LIM),
                                   atol=1e-12)
    Fr, _ = al.keep_along(F0, tau0, f_des, u, tau_des, LEVER, F_LIM, T_LIM, brake_only=False)
    unclipped = F0 + (want - F0 @ u) * u
    if np.all(np.abs(unclipped) <= F_LIM):
        assert Fr @ u == pytest.approx(want, abs=1e-12)
        np.testing.assert_allclose(Fr - (Fr @ u) * u, F0 - (F0 @ u) * u, atol=1e-12)


def test_keep_along_stops_the_lever_pushing_a_braking_pair_ahead():
    """The traced 5 N failure (seed 348, 34 s): the route wants 1 N of braking (-x, the route
    along +x) while the pair, pitched, wants more torque than the limit; allocate pushes the
    pair ahead (+0.68 N along x) to make torque through the lever; kept along the route, the
    force brakes at the limit and only its across-route part helps the turn."""
    f_des, tau_des = np.array([-1.0, 0.0, 0.0]), np.array([0.0, 10 * T_LIM[1], 0.0])
    F0, tau0 = al.allocate(f_des, tau_des, LEVER, F_LIM, T_LIM, 1.0, 3.0)
    assert F0[0] > 0.5 * F_LIM[0]
    F, _ = al.keep_along(F0, tau0, f_des, np.array([1.0, 0, 0]), tau_des, LEVER, F_LIM, T_LIM)
    assert F[0] == pytest.approx(-F_LIM[0])
    assert F[2] == pytest.approx(F0[2])
