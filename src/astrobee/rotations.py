"""Quaternion and rotation helpers. Quaternions are numpy arrays [x, y, z, w] (ROS/pybullet order).

Thin, vectorised wrappers; scipy.spatial.transform.Rotation does the heavy lifting where a
batch is involved. One quaternion (shape (4,)) and one vector (shape (3,)) take a scalar path
in plain floats (the hot loops: the PD law, the env's observation, the sim, the Task monitor
call these once per tick on one pose): it repeats the array path's floating-point operations in
the same order (numpy's reductions over 3-4 elements sum left to right; einsum over a
contiguous 3-vector sums (p0 + p2) + p1; arctan2/arccos/sin/cos are numpy's own ufuncs), so
both paths give the same bits (numpy 2.4; tests/lab/test_rotations.py holds them to 1e-12).
A zero or non-finite quaternion falls through to the array path (its nan and warning).
"""
from __future__ import annotations

import math

import numpy as np

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])
_CONJ = np.array([-1.0, -1.0, -1.0, 1.0])
_ONE = (4,)
_VEC = (3,)


def _unit(q: np.ndarray) -> tuple[float, float, float, float] | None:
    """The normalised components of one float quaternion as floats (None: zero or non-finite
    norm, left to the array path and its nan/warning behaviour)."""
    x, y, z, w = q.tolist()
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not 0.0 < n < math.inf:
        return None
    return x / n, y / n, z / n, w / n


def _matrix(x: float, y: float, z: float, w: float) -> tuple[float, ...]:
    """Row-major entries of to_matrix() of a unit quaternion, as floats."""
    return (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y))


def _rotvec(x: float, y: float, z: float, w: float) -> np.ndarray:
    """to_rotvec() of a unit quaternion given as floats."""
    if w < 0:
        x, y, z, w = -x, -y, -z, -w
    s = math.sqrt(x * x + y * y + z * z)
    if s > 1e-12:
        k = float(2.0 * np.arctan2(s, w)) / s
    else:
        k = 2.0
    return np.array([x * k, y * k, z * k])


def normalize(q: np.ndarray) -> np.ndarray:
    """q / |q| over the last axis."""
    q = np.asarray(q, dtype=float)
    if q.shape == _ONE:
        u = _unit(q)
        if u is not None:
            return np.array(u)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    return q / n


def conjugate(q: np.ndarray) -> np.ndarray:
    """[-x, -y, -z, w]: the inverse rotation of a unit quaternion."""
    return np.asarray(q, dtype=float) * _CONJ


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a*b (apply b, then a) for [x, y, z, w] quaternions; broadcasts."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape == _ONE and b.shape == _ONE:
        ax, ay, az, aw = a.tolist()
        bx, by, bz, bw = b.tolist()
        return np.array([aw * bx + ax * bw + ay * bz - az * by,
                         aw * by - ax * bz + ay * bw + az * bx,
                         aw * bz + ax * by - ay * bx + az * bw,
                         aw * bw - ax * bx - ay * by - az * bz])
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ], axis=-1)


def to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (body -> world) of a unit quaternion; broadcasts over leading axes."""
    q = np.asarray(q, dtype=float)
    if q.shape == _ONE:
        u = _unit(q)
        if u is not None:
            return np.array(_matrix(*u)).reshape(3, 3)
    x, y, z, w = np.moveaxis(normalize(q), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def from_matrix(m: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation
    return Rotation.from_matrix(m).as_quat()


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vector(s) v from the body frame to the world frame by q."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    if q.shape == _ONE and v.shape == _VEC:
        u = _unit(q)
        if u is not None:
            m0, m1, m2, m3, m4, m5, m6, m7, m8 = _matrix(*u)
            a, b, c = v.tolist()
            # einsum's order over the contiguous row: (m0 a + m2 c) + m1 b
            return np.array([m0 * a + m2 * c + m1 * b, m3 * a + m5 * c + m4 * b,
                             m6 * a + m8 * c + m7 * b])
    return np.einsum("...ij,...j->...i", to_matrix(q), v)


def rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vector(s) v from the world frame into the body frame of q."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    if q.shape == _ONE and v.shape == _VEC:
        u = _unit(q)
        if u is not None:
            m0, m1, m2, m3, m4, m5, m6, m7, m8 = _matrix(*u)
            a, b, c = v.tolist()
            # einsum's order down a strided column: left to right
            return np.array([m0 * a + m3 * b + m6 * c, m1 * a + m4 * b + m7 * c,
                             m2 * a + m5 * b + m8 * c])
    return np.einsum("...ji,...j->...i", to_matrix(q), v)


def from_axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    s = np.sin(angle / 2.0)
    return np.array([*(axis * s), np.cos(angle / 2.0)])


def from_rotvec(v: np.ndarray) -> np.ndarray:
    """Quaternion of a rotation vector (axis * angle)."""
    v = np.asarray(v, dtype=float)
    if v.shape == _VEC:
        x, y, z = v.tolist()
        t = math.sqrt(x * x + y * y + z * z)
        half = 0.5 * t
        k = float(np.sin(half)) / t if t > 1e-12 else 0.5 - t * t / 48.0
        return np.array([x * k, y * k, z * k, float(np.cos(half))])
    th = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * th
    k = np.where(th > 1e-12, np.sin(half) / np.where(th > 1e-12, th, 1.0), 0.5 - th**2 / 48.0)
    return np.concatenate([v * k, np.cos(half)], axis=-1)


def to_rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vector of q, taking the short way round (w >= 0)."""
    q = np.asarray(q, dtype=float)
    if q.shape == _ONE:
        u = _unit(q)
        if u is not None:
            return _rotvec(*u)
    q = normalize(q)
    q = np.where(q[..., 3:4] < 0, -q, q)
    v = q[..., :3]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    ang = 2.0 * np.arctan2(s, q[..., 3:4])
    k = np.where(s > 1e-12, ang / np.where(s > 1e-12, s, 1.0), 2.0)
    return v * k


def attitude_error(q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """Rotation vector (body frame of q) that takes q onto q_ref: small-angle attitude error."""
    q = np.asarray(q, dtype=float)
    q_ref = np.asarray(q_ref, dtype=float)
    if q.shape == _ONE and q_ref.shape == _ONE:
        ax, ay, az, aw = q.tolist()
        ax, ay, az = -ax, -ay, -az                      # conjugate(q)
        bx, by, bz, bw = q_ref.tolist()
        x = aw * bx + ax * bw + ay * bz - az * by
        y = aw * by - ax * bz + ay * bw + az * bx
        z = aw * bz + ax * by - ay * bx + az * bw
        w = aw * bw - ax * bx - ay * by - az * bz
        n = math.sqrt(x * x + y * y + z * z + w * w)
        if 0.0 < n < math.inf:
            return _rotvec(x / n, y / n, z / n, w / n)
    return to_rotvec(multiply(conjugate(q), q_ref))


def angle_between(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest rotation angle (rad) between two orientations."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape == _ONE and b.shape == _ONE:
        ua, ub = _unit(a), _unit(b)
        if ua is not None and ub is not None:
            d = abs(ua[0] * ub[0] + ua[1] * ub[1] + ua[2] * ub[2] + ua[3] * ub[3])
            return 2.0 * float(np.arccos(min(1.0, d)))
    d = abs(float(np.dot(normalize(a), normalize(b))))
    return 2.0 * float(np.arccos(min(1.0, d)))


def slerp(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    """Spherical interpolation from a (s = 0) to b (s = 1), the short way round."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape == _ONE and b.shape == _ONE and np.ndim(s) == 0:
        ua, ub = _unit(a), _unit(b)
        if ua is not None and ub is not None:
            return _slerp(ua, ub, float(s))
    a, b = normalize(a), normalize(b)
    d = float(np.dot(a, b))
    if d < 0:
        b, d = -b, -d
    if d > 0.9995:
        return normalize(a + s * (b - a))
    th = np.arccos(d)
    return (np.sin((1 - s) * th) * a + np.sin(s * th) * b) / np.sin(th)


def _slerp(a: tuple[float, ...], b: tuple[float, ...], s: float) -> np.ndarray:
    """slerp() of two unit quaternions given as floats."""
    d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
    if d < 0:
        b, d = tuple(-c for c in b), -d
    if d > 0.9995:
        return normalize(np.array([ai + s * (bi - ai) for ai, bi in zip(a, b)]))
    th = np.arccos(d)
    sa, sb, st = float(np.sin((1 - s) * th)), float(np.sin(s * th)), float(np.sin(th))
    return np.array([(sa * ai + sb * bi) / st for ai, bi in zip(a, b)])


def from_euler(roll: float, pitch: float, yaw: float) -> np.ndarray:
    from scipy.spatial.transform import Rotation
    return Rotation.from_euler("xyz", [roll, pitch, yaw]).as_quat()


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for 3-vectors in plain arithmetic (several times faster than np.cross on one pair)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def step_body(q: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    """q * exp(dtheta) for a BODY-frame rotation vector dtheta, renormalised (rigid-body
    integrators of the sim's rigid backend and the control tests share it)."""
    dtheta = np.asarray(dtheta, dtype=float)
    th = float(np.sqrt(dtheta @ dtheta))
    half = 0.5 * th
    k = float(np.sin(half)) / th if th > 1e-12 else 0.5
    dx, dy, dz = dtheta.tolist()                   # floats: the same IEEE arithmetic, faster
    bx, by, bz, bw = dx * k, dy * k, dz * k, float(np.cos(half))
    ax, ay, az, aw = np.asarray(q, dtype=float).tolist()
    out = np.array([aw * bx + ax * bw + ay * bz - az * by,
                    aw * by - ax * bz + ay * bw + az * bx,
                    aw * bz + ax * by - ay * bx + az * bw,
                    aw * bw - ax * bx - ay * by - az * bz])
    return out / np.sqrt(out @ out)
