import itertools

import numpy as np
import pytest

from astrobee import bezier, config, flight_modes, station
from astrobee import rotations as rot
from astrobee_planning import boxes, planner
from conftest import fibonacci_sphere, module_waypoints

WPS = module_waypoints()
PAIRS = list(itertools.combinations(sorted(WPS), 2))
Q0 = rot.from_euler(0.0, 0.0, 0.3)
Q1 = rot.from_euler(0.1, -0.2, 2.0)


SPHERE = np.vstack([fibonacci_sphere(60), np.eye(3), -np.eye(3)])


def _robot_inside_keep_in(pos: np.ndarray) -> np.ndarray:
    """Per centre: every point of the robot's collision sphere (66 surface points incl. the six
    axis extremes) in some keep-in box of config/iss.yaml (the raw boxes, not the planner's set)."""
    keep_in = config.keep_in_boxes()
    pts = (pos[:, None, :] + station.robot_radius() * SPHERE[None]).reshape(-1, 3)
    inside = np.zeros(len(pts), dtype=bool)
    for b in keep_in:
        inside |= np.all((pts >= b[:3] - 1e-7) & (pts <= b[3:] + 1e-7), axis=1)
    return inside.reshape(len(pos), -1).all(axis=1)


def _check_plan(plan, p0, q0, p1, q1, mode, safe):
    tr, sp = plan.trajectory, plan.spline
    # every control point inside its segment's box (so the curve is)
    for s in range(len(sp.durations)):
        b = sp.boxes[s]
        assert np.all(sp.points[s] >= b[:3] - 1e-7) and np.all(sp.points[s] <= b[3:] + 1e-7)
    # dense sampling: inside the safe set, within every limit
    t = np.linspace(0.0, tr.duration, 4000)
    st = tr.sample(t)
    assert safe.contains_all(st.pos, tol=1e-7).all()
    # the robot's sphere inside the keep-in boxes, densely (at most 2 cm between samples)
    n = max(2000, int(np.linalg.norm(np.diff(st.pos, axis=0), axis=1).sum() / 0.02))
    dense = tr.sample(np.linspace(0.0, tr.duration, n)).pos
    assert _robot_inside_keep_in(dense).all()
    fm = flight_modes.get(mode)
    assert np.linalg.norm(st.vel, axis=1).max() <= fm.hard_limit_vel * (1 + 1e-9)
    assert np.linalg.norm(st.acc, axis=1).max() <= fm.hard_limit_accel * (1 + 1e-9)
    assert np.linalg.norm(st.omega, axis=1).max() <= fm.hard_limit_omega * (1 + 1e-9)
    assert np.linalg.norm(st.alpha, axis=1).max() <= fm.hard_limit_alpha * (1 + 1e-9)
    # continuity of position..jerk at the spline joints, attitude at its breaks
    for k in range(4):
        for s in range(len(sp.durations) - 1):
            left = bezier.derivative_points(sp.points[s], sp.durations[s], k)[-1]
            right = bezier.derivative_points(sp.points[s + 1], sp.durations[s + 1], k)[0]
            assert np.allclose(left, right, atol=1e-7 * max(1.0, np.abs(left).max()))
    eps = 1e-7
    for piece in tr.attitude[1:]:
        a, b = tr.sample([piece.t0 - eps, piece.t0 + eps])[[0]], tr.sample([piece.t0 + eps])
        assert abs(abs(a.quat[0] @ b.quat[0]) - 1) < 1e-9
        assert np.allclose(a.omega[0], b.omega[0], atol=1e-6)
        assert np.allclose(a.alpha[0], b.alpha[0], atol=1e-5)
    # start and end at the requested states, at rest
    ends = tr.sample([0.0, tr.duration])
    np.testing.assert_allclose(ends.pos, [p0, p1], atol=1e-7)
    assert rot.angle_between(ends.quat[0], q0) < 1e-7 and rot.angle_between(ends.quat[1], q1) < 1e-7
    for f in (ends.vel, ends.acc, ends.omega, ends.alpha):
        assert np.abs(f).max() < 1e-7


@pytest.mark.parametrize("a,b", PAIRS)
def test_every_module_pair(a, b, safe):
    plan = planner.plan_global(WPS[a], Q0, WPS[b], Q1, "nominal", safe=safe)
    assert plan.code == planner.SUCCESS
    _check_plan(plan, WPS[a], Q0, WPS[b], Q1, "nominal", safe)


@pytest.mark.parametrize("a,b,mode", [("node_2", "jem", "nominal"), ("jem", "cupola", "nominal"),
                                      ("us_lab", "eu_lab", "difficult"), ("node_1", "node_3", "quiet")])
def test_face_forward(a, b, mode, safe):
    plan = planner.plan_global(WPS[b], Q0, WPS[a], Q1, mode, face_forward=True, safe=safe)
    _check_plan(plan, WPS[b], Q0, WPS[a], Q1, mode, safe)
    # while translating fast, body x points along the velocity
    st = plan.trajectory.sample(np.linspace(0, plan.trajectory.duration, 2000))
    sp = np.linalg.norm(st.vel, axis=1)
    fast = sp > 0.8 * sp.max()
    bx = rot.rotate(st.quat[fast], np.array([1.0, 0, 0]))
    cosang = np.sum(bx * st.vel[fast], axis=1) / sp[fast]
    assert np.median(cosang) > 0.99 and cosang.min() > 0.9


def test_pure_reorientation_and_already_there(safe):
    p = WPS["node_2"]
    plan = planner.plan_global(p, Q0, p, Q1, "nominal", safe=safe)
    assert plan.code == planner.SUCCESS
    st = plan.trajectory.sample(np.linspace(0, plan.trajectory.duration, 500))
    assert np.allclose(st.pos, p)
    assert rot.angle_between(st.quat[-1], Q1) < 1e-9
    assert planner.plan_global(p, Q0, p, Q0, "nominal", safe=safe).code == planner.ALREADY_THERE


@pytest.mark.parametrize("kwargs,code", [
    (dict(goal_pos=[0.0, 0.0, 0.0]), planner.VIOLATES_KEEP_IN),
    (dict(start_pos=[10.95, 9.0, 4.84]), planner.VIOLATES_KEEP_IN),
    (dict(goal_pos=[np.nan, 0.0, 4.84]), planner.INVALID_COMMAND),
    (dict(goal_quat=[0.0, 0.0, 0.0, 1.5]), planner.INVALID_COMMAND),
    (dict(start_quat=[0.0, np.inf, 0.0, 1.0]), planner.INVALID_COMMAND),
    (dict(flight_mode="warp"), planner.INVALID_FLIGHT_MODE),
    (dict(flight_mode="off"), planner.INVALID_FLIGHT_MODE),
    (dict(carry_extent=-1.0), planner.INVALID_COMMAND),
])
def test_bad_input_codes(kwargs, code):
    args = dict(start_pos=WPS["node_2"], start_quat=Q0, goal_pos=WPS["jem"], goal_quat=Q1,
                flight_mode="nominal")
    args.update(kwargs)
    with pytest.raises(planner.PlanError) as exc:
        planner.plan_global(**args)
    assert exc.value.code == code and str(exc.value)


def test_tiny_quaternion_error_tolerated(safe):
    q = Q0 * (1 + 2e-5)
    plan = planner.plan_global(WPS["node_2"], q, WPS["jem"], Q1, "nominal", safe=safe)
    assert plan.code == planner.SUCCESS


def test_unreachable_goal_is_plan_failed():
    """Two disconnected keep-in boxes: goal inside the safe set but not reachable."""
    iso = boxes.safe_set(keep_in=np.array([[0, 0, 0, 2, 2, 2], [5, 5, 5, 7, 7, 7]], float))
    with pytest.raises(planner.PlanError) as exc:
        planner.plan_global([1.0, 1, 1], Q0, [6.0, 6, 6], Q1, "nominal", safe=iso)
    assert exc.value.code == planner.PLAN_FAILED


def test_boundary_velocity():
    """Given non-zero boundary velocities, the spline starts and ends with them."""
    from astrobee_planning.position_planner import plan_position
    v0, v1 = np.array([0.05, 0.0, 0.0]), np.array([0.0, -0.05, 0.0])
    pp = plan_position(WPS["us_lab"], WPS["jem"], 0.2, 0.0175, v0=v0, v1=v1)
    v = pp.spline.evaluate([0.0, pp.spline.duration], 1)
    np.testing.assert_allclose(v, [v0, v1], atol=1e-7)


# the paper's code's trajectory on each route (s), planned rest to rest, nominal
PAPER = {("node_2", "jem"): 60.5, ("jem", "node_1"): 199.3, ("jem", "cupola"): 273.3,
         ("eu_lab", "jem"): 98.8, ("us_lab", "node_3"): 87.6}


@pytest.mark.parametrize("a,b", list(PAPER))
def test_never_slower_than_the_paper_and_few_solves(a, b, safe):
    plan = planner.plan_global(WPS[a], rot.IDENTITY, WPS[b], rot.IDENTITY, "nominal", safe=safe)
    tr = plan.trajectory
    assert tr.duration <= PAPER[(a, b)]
    # a handful of QP solves, not a bisection; and no faster than the trapezoid bound allows
    assert tr.info["solves"] <= 10
    assert tr.duration >= tr.info["lower_bound"] > 0


def test_peak_speed_reaches_the_limit_on_a_long_straight_leg(safe):
    """Node 2 -> JEM is a straight 6 m leg: the plan cruises at the flight mode's speed, and
    its duration is within 10% of the trapezoid's (41.4 s)."""
    fm = flight_modes.get("nominal")
    plan = planner.plan_global(WPS["node_2"], rot.IDENTITY, WPS["jem"], rot.IDENTITY, "nominal", safe=safe)
    st = plan.trajectory.sample_rate(50.0)
    assert np.linalg.norm(st.vel, axis=1).max() >= 0.99 * fm.hard_limit_vel
    assert plan.trajectory.duration <= 1.1 * plan.trajectory.info["lower_bound"]


def test_vectorised_sampling_matches_piecewise_evaluation(safe):
    """Trajectory.sample (cached monomial tables, sorted or not) equals the Bezier and
    quaternion polynomial pieces evaluated one by one."""
    plan = planner.plan_global(WPS["jem"], Q0, WPS["cupola"], Q1, "nominal", face_forward=True, safe=safe)
    tr = plan.trajectory
    t = np.random.default_rng(3).uniform(0.0, tr.duration, 500)
    st = tr.sample(t)
    for i in range(0, 500, 7):
        k = max(j for j, p in enumerate(tr.position) if p.t0 <= t[i])
        p = tr.position[k]
        s = np.clip((t[i] - p.t0) / p.duration, 0.0, 1.0)
        np.testing.assert_allclose(st.pos[i], bezier.evaluate(p.points, [s])[0], atol=1e-9)
        np.testing.assert_allclose(st.vel[i], bezier.evaluate_derivative(p.points, p.duration, [s], 1)[0], atol=1e-10)
        np.testing.assert_allclose(st.acc[i], bezier.evaluate_derivative(p.points, p.duration, [s], 2)[0], atol=1e-10)
        ka = max(j for j, a in enumerate(tr.attitude) if a.t0 <= t[i])
        q = tr.attitude[ka].raw([np.clip((t[i] - tr.attitude[ka].t0) / tr.attitude[ka].duration, 0, 1)])[0]
        assert abs(abs(st.quat[i] @ (q / np.linalg.norm(q))) - 1) < 1e-12


def test_block_sampling_matches_each_piece_with_rates(safe):
    """Long samplings (several BLOCKs, pieces straddling block edges, unsorted times) give every
    piece's own value and world rates, and the quaternion sign stays continuous."""
    from astrobee_planning import trajectory
    plan = planner.plan_global(WPS["jem"], Q0, WPS["cupola"], Q1, "nominal", face_forward=True, safe=safe)
    tr = plan.trajectory
    n = 3 * trajectory.BLOCK + 17
    t = np.random.default_rng(5).permutation(np.linspace(0.0, tr.duration, n))
    st = tr.sample(t)
    for i in range(0, n, 97):
        ka = max(j for j, a in enumerate(tr.attitude) if a.t0 <= t[i])
        q, w, al = tr.attitude[ka].evaluate([t[i]])
        assert abs(abs(st.quat[i] @ q[0]) - 1) < 1e-12
        np.testing.assert_allclose(st.omega[i], w[0], atol=1e-12)
        np.testing.assert_allclose(st.alpha[i], al[0], atol=1e-11)
        k = max(j for j, p in enumerate(tr.position) if p.t0 <= t[i])
        p = tr.position[k]
        s = np.clip((t[i] - p.t0) / p.duration, 0.0, 1.0)
        np.testing.assert_allclose(st.pos[i], bezier.evaluate(p.points, [s])[0], atol=1e-9)
    srt = tr.sample_rate(50.0)
    assert np.all(np.sum(srt.quat[1:] * srt.quat[:-1], axis=1) > 0.99)


@pytest.mark.parametrize("a,b", [("node_2", "jem"), ("jem", "cupola")])
def test_banded_solver_matches_clarabel(a, b, safe):
    """The banded interior-point solve of the spline QP gives Clarabel's optimum (objective
    within 1e-8, equalities to 1e-9, inside the boxes) for the same durations."""
    import scipy.sparse as sp
    from astrobee_planning import position_planner as gp
    from astrobee_planning import spline_qp as qp
    start, goal = WPS[a], WPS[b]
    route = safe.route(start, goal)
    rb = safe.boxes[route]
    poly = gp.reference_polyline(rb, start, goal)
    _, leg_of, T, track = gp.profile_segments(poly, gp.corner_speeds(poly, 0.2, 0.0175), 0.2, 0.0175,
                                              0.2 * gp.DV_FRACTION, gp.MAX_LEG)
    rb = rb[leg_of]
    bc = np.stack([start, np.zeros(3), np.zeros(3), goal, np.zeros(3), np.zeros(3)], axis=1)
    banded = qp.SplineQP(rb[:, :3], rb[:, 3:], qp.DEGREE, qp.CONTINUITY, track, gp.TRACK_WEIGHT)
    ref = qp.SplineQP(rb[:, :3], rb[:, 3:], qp.DEGREE, qp.CONTINUITY, track, gp.TRACK_WEIGHT)
    ref._solve_banded = lambda *args, **kw: None
    for Ts in (T, T * np.linspace(0.7, 1.6, len(T))):
        xb, xc = banded.solve(Ts, bc), ref.solve(Ts, bc)
        assert banded.fallbacks == 0 and ref.fallbacks > 0
        tm = float(np.mean(Ts))
        P = banded._p.copy()
        P.data = banded._p_base * (tm / Ts[banded._p_seg]) ** 5 + banded._p_diag_track
        P = P + sp.triu(P, 1).T
        A = banded._a.copy()
        A.data = banded._base * banded._scales(Ts)[banded._scl]
        A = A.toarray()[:banded.n_eq]
        beq = banded._b(Ts, bc)[:banded.n_eq]
        f = lambda x: 0.5 * x @ (P @ x) + banded._q @ x  # noqa: E731
        vb, vc = (x.transpose(2, 0, 1).reshape(-1) for x in (xb, xc))
        assert f(vb) <= f(vc) + 1e-8 * abs(f(vc))
        assert np.abs(A @ vb - beq).max() <= 1e-9 * max(1.0, np.abs(beq).max())
        assert np.all(xb >= rb[:, None, :3]) and np.all(xb <= rb[:, None, 3:])
