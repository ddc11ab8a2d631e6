"""Quaternion and rotation helpers. Quaternions are numpy arrays [x, y, z, w] (ROS/pybullet order).

Thin, vectorised wrappers; scipy.spatial.transform.Rotation does the heavy lifting where a
batch is involved.
"""
from __future__ import annotations

import numpy as np

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def normalize(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    return q / n


def conjugate(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a*b (apply b, then a) for [x, y, z, w] quaternions; broadcasts."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
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
    return np.einsum("...ij,...j->...i", to_matrix(q), np.asarray(v, dtype=float))


def rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vector(s) v from the world frame into the body frame of q."""
    return np.einsum("...ji,...j->...i", to_matrix(q), np.asarray(v, dtype=float))


def from_axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    s = np.sin(angle / 2.0)
    return np.array([*(axis * s), np.cos(angle / 2.0)])


def from_rotvec(v: np.ndarray) -> np.ndarray:
    """Quaternion of a rotation vector (axis * angle)."""
    v = np.asarray(v, dtype=float)
    th = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * th
    k = np.where(th > 1e-12, np.sin(half) / np.where(th > 1e-12, th, 1.0), 0.5 - th**2 / 48.0)
    return np.concatenate([v * k, np.cos(half)], axis=-1)


def to_rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vector of q, taking the short way round (w >= 0)."""
    q = normalize(q)
    q = np.where(q[..., 3:4] < 0, -q, q)
    v = q[..., :3]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    ang = 2.0 * np.arctan2(s, q[..., 3:4])
    k = np.where(s > 1e-12, ang / np.where(s > 1e-12, s, 1.0), 2.0)
    return v * k


def attitude_error(q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """Rotation vector (body frame of q) that takes q onto q_ref: small-angle attitude error."""
    return to_rotvec(multiply(conjugate(q), q_ref))


def angle_between(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest rotation angle (rad) between two orientations."""
    d = abs(float(np.dot(normalize(a), normalize(b))))
    return 2.0 * float(np.arccos(min(1.0, d)))


def slerp(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    a, b = normalize(a), normalize(b)
    d = float(np.dot(a, b))
    if d < 0:
        b, d = -b, -d
    if d > 0.9995:
        return normalize(a + s * (b - a))
    th = np.arccos(d)
    return (np.sin((1 - s) * th) * a + np.sin(s * th) * b) / np.sin(th)


def from_euler(roll: float, pitch: float, yaw: float) -> np.ndarray:
    from scipy.spatial.transform import Rotation
    return Rotation.from_euler("xyz", [roll, pitch, yaw]).as_quat()


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for 3-vectors in plain arithmetic (several times faster than np.cross on one pair)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def step_body(q: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    """q * exp(dtheta) for a BODY-frame rotation vector dtheta, renormalised (rigid-body
    integrators of the sim's rigid backend and the control tests share it)."""
    th = float(np.sqrt(dtheta @ dtheta))
    k = np.sin(0.5 * th) / th if th > 1e-12 else 0.5
    bx, by, bz = dtheta * k
    bw = np.cos(0.5 * th)
    ax, ay, az, aw = q
    out = np.array([aw * bx + ax * bw + ay * bz - az * by,
                    aw * by - ax * bz + ay * bw + az * bx,
                    aw * bz + ax * by - ay * bx + az * bw,
                    aw * bw - ax * bx - ay * by - az * bz])
    return out / np.sqrt(out @ out)
