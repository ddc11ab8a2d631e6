"""The pair model's CasADi form: astrobee_control.pair_model.derivative on CasADi symbols (one
definition, one parameter set), plus an RK4 step for multiple shooting."""
from __future__ import annotations

import tempfile
from typing import Any

from astrobee_control import pair_model as pm


def casadi_derivative(params: pm.PairParams) -> Any:
    """casadi.Function f(x[26], u[6], bump[3]) -> dx/dt[26]."""
    import casadi as ca
    x, u, b = ca.SX.sym("x", pm.NX), ca.SX.sym("u", pm.NU), ca.SX.sym("bump", 3)
    out = pm.derivative([x[i] for i in range(pm.NX)], [u[i] for i in range(pm.NU)],
                        [b[i] for i in range(3)], params)
    return ca.Function("pair_xdot", [x, u, b], [ca.vertcat(*out)])


_STEPS: dict = {}


def casadi_step(params: pm.PairParams, substeps: int = 1, jit: bool = False) -> Any:
    """casadi.Function F(x, u, bump, h) -> x after h s (RK4, `substeps` steps, quaternions
    renormalised after each as pair_model.rk4 does). jit: the derivative (and the derivatives of
    it that IPOPT's Hessian needs) compiled by the C compiler: evaluating them is ~all of the
    oracle's solve time otherwise. The RK4 is an MX graph of calls to that small function."""
    key = (params, substeps, jit)
    if key in _STEPS:           # one Function per process: its compiled derivatives are reused
        return _STEPS[key]
    import casadi as ca
    opts = {"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O1"], "verbose": False,
                                                       "directory": tempfile.gettempdir()}} \
        if jit else {}
    xs, us, bs = ca.SX.sym("x", pm.NX), ca.SX.sym("u", pm.NU), ca.SX.sym("bump", 3)
    out = pm.derivative([xs[i] for i in range(pm.NX)], [us[i] for i in range(pm.NU)],
                        [bs[i] for i in range(3)], params)
    f = ca.Function("pair_xdot", [xs, us, bs], [ca.vertcat(*out)], opts)
    x, u, b, h = ca.MX.sym("x", pm.NX), ca.MX.sym("u", pm.NU), ca.MX.sym("bump", 3), ca.MX.sym("h")
    dt = h / substeps
    xk = x
    for _ in range(substeps):
        k1 = f(xk, u, b)
        k2 = f(xk + 0.5 * dt * k1, u, b)
        k3 = f(xk + 0.5 * dt * k2, u, b)
        k4 = f(xk + dt * k3, u, b)
        xk = xk + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        qr, qb = xk[6:10], xk[13:17]
        xk = ca.vertcat(xk[0:6], qr / ca.norm_2(qr), xk[10:13], qb / ca.norm_2(qb), xk[17:])
    _STEPS[key] = ca.Function("pair_step", [x, u, b, h], [xk])
    return _STEPS[key]


def casadi_points(params: pm.PairParams, bag_points) -> Any:
    """casadi.Function P(x) -> (robot centre (3), bag points (3 K) world) of a state;
    bag_points (K, 3) in the bag frame, about its centre."""
    import casadi as ca
    x = ca.SX.sym("x", pm.NX)
    Rr = ca.vertcat(*[ca.horzcat(*row) for row in pm._matrix([x[i] for i in range(6, 10)])])
    Rb = ca.vertcat(*[ca.horzcat(*row) for row in pm._matrix([x[i] for i in range(13, 17)])])
    centre = x[0:3] + Rr @ ca.DM(params.grasp_robot) - Rb @ ca.DM(params.grasp_bag)
    pts = [centre + Rb @ ca.DM(list(map(float, c))) for c in bag_points]
    return ca.Function("pair_points", [x], [x[0:3], ca.vertcat(*pts) if pts else ca.DM.zeros(0)])
