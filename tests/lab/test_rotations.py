"""astrobee.rotations: the single-quaternion scalar paths equal the array paths (to 1e-12; they
are built to be bit-identical) on thousands of random quaternions and the edge cases, and both
agree with scipy's Rotation."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from astrobee import rotations as rot

TOL = 1e-12
N = 3000
S = math.sqrt(0.5)

EDGES = np.array([
    [0.0, 0.0, 0.0, 1.0],            # identity
    [0.0, 0.0, 0.0, -1.0],           # identity, negative w
    [0.0, 0.0, 0.0, 2.5],            # identity, unnormalised
    [1.0, 0.0, 0.0, 0.0],            # 180 degrees about x, y, z
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, -3.0, 0.0],           # 180 degrees, unnormalised
    [0.6, 0.0, 0.8, 0.0],            # 180 degrees about an oblique axis
    [1e-14, 0.0, 0.0, 1.0],          # below the rotation-vector cut-off
    [0.0, 0.0, S, S],                # 90 degrees
    [0.0, 0.0, S, -S],               # the same, negative w
    [0.5, 0.5, 0.5, -0.5],
    [1e3, -2e3, 5e2, 1e2],           # far from unit
    [1e-3, 2e-3, -1e-3, -4e-3],
])


@pytest.fixture(scope="module")
def data() -> dict[str, np.ndarray]:
    """Random quaternions (unnormalised, both signs of w) with the edge cases first, a second
    set with the edge cases paired against each other (equal, opposite, near), vectors."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=(N, 4)) * rng.uniform(0.05, 20.0, size=(N, 1))
    p = rng.normal(size=(N, 4))
    v = rng.normal(size=(N, 3)) * rng.uniform(0.01, 3.0, size=(N, 1))
    k = len(EDGES)
    q[:k] = EDGES
    p[:k] = EDGES[::-1]
    p[k:2 * k] = EDGES                             # edge cases against random ones
    p[2 * k:2 * k + 10] = q[2 * k:2 * k + 10]      # identical
    p[2 * k + 10:2 * k + 20] = -3.0 * q[2 * k + 10:2 * k + 20]   # same rotation, opposite sign
    p[2 * k + 20:2 * k + 30] = q[2 * k + 20:2 * k + 30] + 1e-4 * p[2 * k + 20:2 * k + 30]
    v[:6] = [[0, 0, 0], [1e-13, 0, 0], [math.pi, 0, 0], [0, 0, -math.pi], [1e-6, -2e-6, 0],
             [0, 3.0, 4.0]]
    s = rng.uniform(0.0, 1.0, N)
    s[:3] = [0.0, 1.0, 0.5]
    return {"q": q, "p": p, "v": v, "s": s}


def rows(f, *arrays) -> np.ndarray:
    """f applied to one row (one quaternion or vector) at a time: the scalar path."""
    return np.array([f(*args) for args in zip(*arrays)])


def close(a, b) -> None:
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype
    np.testing.assert_allclose(a, b, rtol=0, atol=TOL)


def unit(a: np.ndarray) -> np.ndarray:
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def test_single_equals_batch_for_the_quaternion_functions(data):
    q, p, v = data["q"], data["p"], data["v"]
    close(rows(rot.normalize, q), rot.normalize(q))
    close(rows(rot.conjugate, q), rot.conjugate(q))
    close(rows(rot.multiply, q, p), rot.multiply(q, p))
    close(rows(rot.to_matrix, q), rot.to_matrix(q))
    close(rows(rot.rotate, q, v), rot.rotate(q, v))
    close(rows(rot.rotate_inverse, q, v), rot.rotate_inverse(q, v))
    close(rows(rot.to_rotvec, q), rot.to_rotvec(q))
    close(rows(rot.from_rotvec, v), rot.from_rotvec(v))
    close(rows(rot.attitude_error, q, p), rot.attitude_error(q, p))


def test_single_equals_array_formula_for_angle_and_slerp(data):
    """angle_between and slerp have no batch form: their array formula, row-wise in numpy."""
    q, p, s = data["q"], data["p"], data["s"]
    a, b = unit(q), unit(p)
    d = np.sum(a * b, axis=-1)
    close(rows(rot.angle_between, q, p), 2.0 * np.arccos(np.minimum(1.0, np.abs(d))))
    b = np.where(d[:, None] < 0, -b, b)
    d = np.abs(d)
    th = np.arccos(np.minimum(d, 1.0))[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):      # the near rows take `near`
        far = (np.sin((1 - s[:, None]) * th) * a + np.sin(s[:, None] * th) * b) / np.sin(th)
    near = unit(a + s[:, None] * (b - a))
    want = np.where(d[:, None] > 0.9995, near, far)
    close(rows(rot.slerp, q, p, s), want)


def test_both_paths_agree_with_scipy(data):
    q, v = data["q"], data["v"]
    r = Rotation.from_quat(q)
    close(rows(rot.to_matrix, q), rot.to_matrix(q))
    np.testing.assert_allclose(rows(rot.to_matrix, q), r.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(rows(rot.rotate, q, v), r.apply(v), atol=1e-12)
    np.testing.assert_allclose(rows(rot.rotate_inverse, q, v), r.inv().apply(v), atol=1e-12)
    # scipy's rotation vector is the short way round except at exactly 180 degrees
    mine = rows(rot.to_rotvec, q)
    theirs = r.as_rotvec()
    half_turn = np.abs(np.linalg.norm(theirs, axis=1) - math.pi) < 1e-9
    np.testing.assert_allclose(mine[~half_turn], theirs[~half_turn], atol=1e-9)
    np.testing.assert_allclose(np.abs(mine[half_turn]), np.abs(theirs[half_turn]), atol=1e-9)
    back = Rotation.from_quat(rows(rot.from_rotvec, data["v"]))
    np.testing.assert_allclose(back.as_rotvec(), Rotation.from_rotvec(data["v"]).as_rotvec(),
                               atol=1e-9)


def test_edge_values():
    ident = np.array([0.0, 0.0, 0.0, 1.0])
    for q in ([0, 0, 0, 1.0], [0, 0, 0, -1.0], [0, 0, 0, 7.0]):
        assert np.array_equal(rot.to_matrix(q), np.eye(3))
        assert np.array_equal(np.abs(rot.to_rotvec(q)), np.zeros(3))
        assert rot.angle_between(q, ident) == 0.0
    np.testing.assert_allclose(rot.to_rotvec([0, 0, 1.0, 0]), [0, 0, math.pi], atol=TOL)
    np.testing.assert_allclose(rot.rotate([1.0, 0, 0, 0], [0, 1.0, 2.0]), [0, -1.0, -2.0],
                               atol=TOL)
    assert rot.angle_between([0, 1.0, 0, 0], ident) == pytest.approx(math.pi, abs=1e-12)
    # negative w: same rotation, the short way round
    q = np.array([0.1, -0.2, 0.3, -0.9])
    close(rot.to_rotvec(q), rot.to_rotvec(-q))
    close(rot.to_matrix(q), rot.to_matrix(-q))


def test_input_kinds_and_degenerate_inputs():
    """Lists, tuples, float32 and ints take the scalar path with the array path's result; a
    zero or non-finite quaternion keeps the array path's nan."""
    q = [0.1, -0.2, 0.3, 0.9]
    v = (1, 2, 3)
    batch_q, batch_v = np.array([q]), np.array([v], float)
    for f, args, batch in [(rot.normalize, (q,), (batch_q,)),
                           (rot.to_matrix, (tuple(q),), (batch_q,)),
                           (rot.rotate, (q, v), (batch_q, batch_v)),
                           (rot.rotate_inverse, (np.float32(q), v), (batch_q.astype(np.float32),
                                                                     batch_v)),
                           (rot.to_rotvec, (q,), (batch_q,)),
                           (rot.from_rotvec, (v,), (batch_v,))]:
        close(f(*args), f(*batch)[0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for bad in ([0.0, 0, 0, 0], [np.nan, 0, 0, 1.0], [np.inf, 0, 0, 1.0]):
            for f in (rot.normalize, rot.to_matrix, rot.to_rotvec):
                single, batch = f(bad), f(np.array([bad]))[0]
                assert np.array_equal(single, batch, equal_nan=True)
                assert np.isnan(single).any()
            assert np.isnan(rot.rotate(bad, v)).all()


def test_one_quaternion_many_vectors_broadcasts(data):
    q, v = data["q"][20], data["v"]
    close(rot.rotate(q, v), rows(lambda x: rot.rotate(q, x), v))
    close(rot.rotate_inverse(q, v), rows(lambda x: rot.rotate_inverse(q, x), v))
    close(rot.multiply(q, data["p"]), rows(lambda x: rot.multiply(q, x), data["p"]))


def test_step_body_is_the_product_with_the_rotation_vector(data):
    """step_body(q, d) (the rigid integrators' scalar path) = normalize(q * exp(d))."""
    q, v = rot.normalize(data["q"]), data["v"] * 0.05
    got = rows(rot.step_body, q, v)
    want = rot.normalize(rot.multiply(q, rot.from_rotvec(v)))
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL)
    close(rot.step_body([0, 0, 0, 1.0], np.zeros(3)), np.array([0, 0, 0, 1.0]))
