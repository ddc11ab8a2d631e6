"""The reduced pair model with the swing: robot and bag two rigid bodies joined at the grasp.

The grasp is a spherical pivot (a ball joint at the gripper) held by a rotational spring-damper
whose stiffness and damping are given per robot body axis: the strap's twist axis stiff-ish, the
two pivot axes soft (config/reduced_models.yaml `pair:`, identified by bench/oracle_sysid.py).
Newton-Euler for both bodies with gyroscopic terms; the joint's constraint force is solved in
closed form (a 3x3 system), so the state is minimal and cannot drift apart:

    x = [p_r (3), v_r (3), q_r (4, xyzw, body -> world), w_r (3, body),
         q_b (4), w_b (3, body), a (6, the applied body wrench: the propulsion lag's state)]

The bag's centre is p_r + R_r g_r - R_b g_b (g_r: grasp in the robot frame, g_b: grasp from the
bag's centre in the bag frame). The commanded body wrench u (6) is boxed per axis (flight mode)
and reaches the robot through a first-order lag of time constant `lag` (0: none); a world force
on the bag's centre (a bump) and a linear drag on the bag's velocity complete it. The joint's
angle is the skew part of the relative rotation (sin(angle) times the axis, exact for small
swings and smooth everywhere), so the same equations are polynomial in the state.

One definition serves two backends: the equations below use only + - * / on 3-tuples of
components, so with numpy arrays they run batched (`rollout`, any leading shape) and with CasADi
symbols they build the oracle's symbolic form (astrobee_lab.oracle.model) from the same
parameters. Nothing here imports CasADi.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

NX, NU = 26, 6
P_R, V_R, Q_R, W_R, Q_B, W_B, A = (slice(0, 3), slice(3, 6), slice(6, 10), slice(10, 13),
                                   slice(13, 17), slice(17, 20), slice(20, 26))


@dataclass(frozen=True)
class PairParams:
    """Everything the pair model needs (one owner: config/reduced_models.yaml `pair:`)."""

    robot_mass: float = 9.583788668
    robot_inertia: tuple = (0.15343, 0.14271, 0.16230)   # kg m^2, body diagonal
    bag_mass: float = 10.0
    bag_inertia: tuple = (0.199, 0.260, 0.355)            # kg m^2, bag-frame diagonal (box)
    grasp_robot: tuple = (-0.20, 0.0, -0.064)             # m, gripper point, robot body frame
    grasp_bag: tuple = (0.284, 0.0, 0.0)                  # m, bag centre -> grasp, bag frame
    stiffness: tuple = (0.05, 0.0, 0.0)                   # N m/rad per robot body axis
    damping: tuple = (0.02, 0.0, 0.0)                     # N m s/rad (defaults: the strap
                                                          # grasp's twist figures, bags.yaml)
    bag_drag: float = 0.0                                 # N s/m on the bag centre's velocity
    lag: float = 0.0                                      # s, propulsion first-order lag
    identification: dict = field(default_factory=dict, compare=False)

    @classmethod
    def from_dict(cls, d: dict) -> "PairParams":
        known = {f for f in cls.__dataclass_fields__}
        extra = sorted(set(d) - known - {"kind"})
        if extra:
            raise ValueError(f"pair parameters: unknown key {extra[0]!r}")
        kw = {k: (tuple(float(x) for x in v) if isinstance(v, (list, tuple)) else v)
              for k, v in d.items() if k in known and k != "identification"}
        p = cls(**kw, identification=dict(d.get("identification") or {}))
        if not (p.robot_mass > 0 and p.bag_mass > 0 and min(p.robot_inertia) > 0
                and min(p.bag_inertia) > 0 and min(p.stiffness) >= 0 and min(p.damping) >= 0
                and p.bag_drag >= 0 and p.lag >= 0):
            raise ValueError("pair parameters: masses and inertias > 0; stiffness, damping, "
                             "drag and lag >= 0")
        return p

    def to_dict(self) -> dict:
        r = lambda v: [round(float(x), 6) for x in v] if isinstance(v, tuple) else v  # noqa: E731
        return {"kind": "pair", **{k: r(v) for k, v in asdict(self).items()}}

    def with_(self, **kw: Any) -> "PairParams":
        return replace(self, **kw)

    def rest_offset(self) -> np.ndarray:
        """Robot -> bag centre at rest (robot body frame, bag frame aligned with it)."""
        return np.asarray(self.grasp_robot) - np.asarray(self.grasp_bag)


def load(name: str = "fem") -> PairParams:
    """The identified pair parameters of bag model `name` (config/reduced_models.yaml `pair:`);
    the defaults when the file records none. ValueError (one line, the recorded names) for a
    name the file does not have: a misspelled name must not fly on the defaults."""
    from astrobee import config
    try:
        data = config.load_yaml("reduced_models.yaml")
    except config.ConfigError:
        return PairParams()
    section = data.get("pair") or {}
    if not section:
        return PairParams()
    if name not in section:
        raise ValueError(f"pair model {name!r}: no such entry under `pair:` in "
                         f"config/reduced_models.yaml (recorded: {', '.join(sorted(section))})")
    return PairParams.from_dict(section[name])


def store(name: str, params: PairParams, identification: dict, path=None) -> None:
    """Record `params` (with how they were identified) as `pair: <name>:` in
    config/reduced_models.yaml (or `path`): the entry's old text is replaced where it stands, a
    new one appended to the section; every other line of the file, comments included, stays."""
    import yaml
    from astrobee import config
    from pathlib import Path
    path = Path(path) if path is not None else config.config_dir() / "reduced_models.yaml"
    d = params.to_dict()
    d["identification"] = identification
    entry = ["  " + line for line in yaml.safe_dump({name: d}, sort_keys=False).splitlines()]
    lines = path.read_text().splitlines()
    if "pair:" not in lines:
        lines += ["pair:"]
    top = lines.index("pair:")
    # the section ends at the next unindented line (a key or a comment), an entry at the next
    # line indented as it is (the next entry or a comment on it)
    end = next((i for i in range(top + 1, len(lines)) if lines[i][:1].strip()), len(lines))
    start = next((i for i in range(top + 1, end) if lines[i] == f"  {name}:"), None)
    if start is None:
        stop = start = end
    else:
        stop = next((i for i in range(start + 1, end) if lines[i][:2] == "  "
                     and lines[i][2:3].strip()), end)
    while stop > start and not lines[stop - 1].strip():       # blank lines stay outside
        stop -= 1
    lines[min(start, stop):stop] = entry
    path.write_text("\n".join(lines) + "\n")


# ---- component arithmetic (numpy arrays or CasADi symbols alike) ------------------------------
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _add(*vs):
    return tuple(sum(c) for c in zip(*vs))


def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _scale(s, a):
    return (s * a[0], s * a[1], s * a[2])


def _mul(d, a):            # per-component product (a diagonal matrix times a vector)
    return (d[0] * a[0], d[1] * a[1], d[2] * a[2])


def _matrix(q):
    """Rows of the rotation matrix of quaternion q (xyzw); q need not be unit (normalised)."""
    x, y, z, w = q
    n = x * x + y * y + z * z + w * w
    s = 2.0 / n
    return ((1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w)),
            (s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w)),
            (s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y)))


def _mv(R, v):             # R v
    return tuple(R[i][0] * v[0] + R[i][1] * v[1] + R[i][2] * v[2] for i in range(3))


def _mtv(R, v):            # R^T v
    return tuple(R[0][i] * v[0] + R[1][i] * v[1] + R[2][i] * v[2] for i in range(3))


def _qdot(q, w):
    """d/dt of quaternion q (xyzw) turning at body rate w: q (x) [w, 0] / 2."""
    x, y, z, s = q
    return (0.5 * (s * w[0] + y * w[2] - z * w[1]), 0.5 * (s * w[1] + z * w[0] - x * w[2]),
            0.5 * (s * w[2] + x * w[1] - y * w[0]), -0.5 * (x * w[0] + y * w[1] + z * w[2]))


def _solve3(K, b):
    """x with K x = b for a 3x3 K given as columns (Cramer's rule)."""
    c0, c1, c2 = K
    det = c0[0] * (c1[1] * c2[2] - c1[2] * c2[1]) - c1[0] * (c0[1] * c2[2] - c0[2] * c2[1]) \
        + c2[0] * (c0[1] * c1[2] - c0[2] * c1[1])

    def d(a, b_, c):
        return a[0] * (b_[1] * c[2] - b_[2] * c[1]) - b_[0] * (a[1] * c[2] - a[2] * c[1]) \
            + c[0] * (a[1] * b_[2] - a[2] * b_[1])
    return (d(b, c1, c2) / det, d(c0, b, c2) / det, d(c0, c1, b) / det)


def derivative(x, u, bump, p: PairParams):
    """dx/dt as a 26-list of components. x: 26 components, u: the 6 commanded body-wrench
    components (already within their box), bump: 3 world force components on the bag's centre."""
    pr, vr, qr, wr = x[0:3], x[3:6], x[6:10], x[10:13]
    qb, wb, a = x[13:17], x[17:20], x[20:26]
    if p.lag > 0:
        da = [(u[i] - a[i]) / p.lag for i in range(6)]
        act = a
    else:
        da, act = [0.0 * a[i] for i in range(6)], u
    Rr, Rb = _matrix(qr), _matrix(qb)
    Ir, Ib = p.robot_inertia, p.bag_inertia
    iIr, iIb = tuple(1.0 / v for v in Ir), tuple(1.0 / v for v in Ib)
    mr, mb = p.robot_mass, p.bag_mass
    rr = _mv(Rr, p.grasp_robot)                      # robot centre -> grasp (world)
    sb = _mv(Rb, p.grasp_bag)                        # bag centre -> grasp (world)
    om_r, om_b = _mv(Rr, wr), _mv(Rb, wb)            # world rates
    vb = _sub(_add(vr, _cross(om_r, rr)), _cross(om_b, sb))
    # joint torque on the bag (robot body axes): skew part of R_r^T R_b (rest: aligned)
    M = [_mtv(Rr, (Rb[0][j], Rb[1][j], Rb[2][j])) for j in range(3)]   # columns of R_r^T R_b
    phi = (0.5 * (M[1][2] - M[2][1]), 0.5 * (M[2][0] - M[0][2]), 0.5 * (M[0][1] - M[1][0]))
    wrel = _mtv(Rr, _sub(om_b, om_r))
    tj = _mv(Rr, _scale(-1.0, _add(_mul(p.stiffness, phi), _mul(p.damping, wrel))))
    Fr = _mv(Rr, act[0:3])
    Tr = _mv(Rr, act[3:6])
    Fb = _sub(tuple(bump), _scale(p.bag_drag, vb))

    def inv_r(v):          # world inverse inertia of the robot times v
        return _mv(Rr, _mul(iIr, _mtv(Rr, v)))

    def inv_b(v):
        return _mv(Rb, _mul(iIb, _mtv(Rb, v)))
    # angular accelerations without the joint force lambda (gyroscopic terms included)
    Ar = inv_r(_sub(_sub(Tr, _mv(Rr, _cross(wr, _mul(Ir, wr)))), tj))
    Ab = inv_b(_sub(tj, _mv(Rb, _cross(wb, _mul(Ib, wb)))))
    # K lambda = b: the grasp points' accelerations agree (lambda: force on the bag at the grasp)
    s = 1.0 / mr + 1.0 / mb

    def K_of(e):
        return _add(_scale(s, e), _cross(inv_r(_cross(rr, e)), rr), _cross(inv_b(_cross(sb, e)), sb))
    K = [K_of(e) for e in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))]
    b = _add(_sub(_scale(1.0 / mr, Fr), _scale(1.0 / mb, Fb)),
             _sub(_cross(Ar, rr), _cross(Ab, sb)),
             _sub(_cross(om_r, _cross(om_r, rr)), _cross(om_b, _cross(om_b, sb))))
    lam = _solve3(K, b)
    ar = _scale(1.0 / mr, _sub(Fr, lam))
    al_r = _sub(Ar, inv_r(_cross(rr, lam)))
    al_b = _add(Ab, inv_b(_cross(sb, lam)))
    return [*vr, *ar, *_qdot(qr, wr), *_mtv(Rr, al_r), *_qdot(qb, wb), *_mtv(Rb, al_b), *da]


# ---- numpy: batched states, RK4 ---------------------------------------------------------------
def xdot(x: np.ndarray, u: np.ndarray, bump: np.ndarray | None, p: PairParams) -> np.ndarray:
    """dx/dt for states x (..., 26), commands u (..., 6) (boxed by the caller), bump (..., 3)."""
    x = np.asarray(x, float)
    u = np.broadcast_to(np.asarray(u, float), x.shape[:-1] + (6,))
    b = np.zeros(x.shape[:-1] + (3,)) if bump is None else \
        np.broadcast_to(np.asarray(bump, float), x.shape[:-1] + (3,))
    out = derivative(list(np.moveaxis(x, -1, 0)), list(np.moveaxis(u, -1, 0)),
                     list(np.moveaxis(b, -1, 0)), p)
    return np.stack(np.broadcast_arrays(*out), -1)


def rk4(x: np.ndarray, u: np.ndarray, bump: np.ndarray | None, p: PairParams, dt: float,
        substeps: int = 1) -> np.ndarray:
    """x after dt seconds of constant u and bump (RK4, `substeps` steps, quaternions renormalised)."""
    h = dt / substeps
    for _ in range(substeps):
        k1 = xdot(x, u, bump, p)
        k2 = xdot(x + 0.5 * h * k1, u, bump, p)
        k3 = xdot(x + 0.5 * h * k2, u, bump, p)
        k4 = xdot(x + h * k3, u, bump, p)
        x = x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
        x = normalise(x)
    return x


def normalise(x: np.ndarray) -> np.ndarray:
    x = np.array(x, float)
    for sl in (Q_R, Q_B):
        x[..., sl] /= np.linalg.norm(x[..., sl], axis=-1, keepdims=True)
    return x


def box(u: np.ndarray, max_force, max_torque) -> np.ndarray:
    """u clipped to the flight mode's per-axis body-wrench box."""
    lim = np.concatenate([np.asarray(max_force, float), np.asarray(max_torque, float)])
    return np.clip(u, -lim, lim)


def rollout(x0: np.ndarray, us: np.ndarray, dt: float, p: PairParams,
            bumps: np.ndarray | None = None, substeps: int = 1, limits=None) -> np.ndarray:
    """States (..., M+1, 26) from x0 (..., 26) under commands us (..., M, 6) held dt s each
    (bumps (..., M, 3) or None; limits (max_force, max_torque) boxes the commands)."""
    us = np.asarray(us, float)
    if limits is not None:
        us = box(us, *limits)
    m = us.shape[-2]
    x = np.asarray(x0, float)
    out = [x]
    for i in range(m):
        x = rk4(x, us[..., i, :], None if bumps is None else bumps[..., i, :], p, dt, substeps)
        out.append(x)
    return np.stack(out, -2)


# ---- state helpers ---------------------------------------------------------------------------
def rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) xyzw."""
    R = _matrix(list(np.moveaxis(np.asarray(q, float), -1, 0)))
    return np.stack([np.stack(np.broadcast_arrays(*row), -1) for row in R], -2)


def bag_centre(x: np.ndarray, p: PairParams) -> tuple[np.ndarray, np.ndarray]:
    """The bag centre's position and velocity (world, (..., 3)) of states x (..., 26)."""
    Rr, Rb = rotation(x[..., Q_R]), rotation(x[..., Q_B])
    rr = Rr @ np.asarray(p.grasp_robot)
    sb = Rb @ np.asarray(p.grasp_bag)
    om_r = (Rr @ x[..., W_R, None])[..., 0]
    om_b = (Rb @ x[..., W_B, None])[..., 0]
    return x[..., P_R] + rr - sb, x[..., V_R] + np.cross(om_r, rr) - np.cross(om_b, sb)


def state(robot_position, robot_velocity, robot_q, robot_omega_body, bag_q, bag_omega_body,
          wrench=None) -> np.ndarray:
    """A state vector (26,) from its parts (quaternions xyzw, rates in each body's frame)."""
    a = np.zeros(6) if wrench is None else np.asarray(wrench, float)
    return np.concatenate([robot_position, robot_velocity, robot_q, robot_omega_body, bag_q,
                           bag_omega_body, a]).astype(float)


def momentum(x: np.ndarray, p: PairParams) -> tuple[np.ndarray, np.ndarray]:
    """Linear momentum and angular momentum about the world origin of states x (..., 26)."""
    pb, vb = bag_centre(x, p)
    Rr, Rb = rotation(x[..., Q_R]), rotation(x[..., Q_B])
    lin = p.robot_mass * x[..., V_R] + p.bag_mass * vb
    Lr = (Rr @ (np.asarray(p.robot_inertia) * x[..., W_R])[..., None])[..., 0]
    Lb = (Rb @ (np.asarray(p.bag_inertia) * x[..., W_B])[..., None])[..., 0]
    ang = Lr + Lb + np.cross(x[..., P_R], p.robot_mass * x[..., V_R]) + np.cross(pb, p.bag_mass * vb)
    return lin, ang
