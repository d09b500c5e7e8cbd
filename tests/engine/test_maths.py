"""Quaternions, matrices, Euler angles, look-at and TRS transforms (engine.maths)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.maths import (
    look_at_quat,
    normalize,
    quat_conjugate,
    quat_from_axis_angle,
    quat_from_euler_deg,
    quat_from_matrix,
    quat_multiply,
    quat_to_euler_deg,
    quat_to_matrix,
    rotate,
    transform_points,
    transform_vectors,
    trs_inverse,
    trs_matrix,
)

finite = st.floats(min_value=-100.0, max_value=100.0, allow_nan=False, allow_infinity=False)
vec3s = st.tuples(finite, finite, finite)
quats = (
    st.tuples(*[st.floats(-1.0, 1.0, allow_nan=False)] * 4)
    .filter(lambda q: math.sqrt(sum(c * c for c in q)) > 0.1)
    .map(lambda q: normalize(q))
)
scales = st.tuples(*[st.one_of(st.floats(0.05, 20.0), st.floats(-20.0, -0.05))] * 3)
FAST = settings(max_examples=60, deadline=None)


def same_rotation(a: np.ndarray, b: np.ndarray, atol: float = 1e-9) -> bool:
    """q and -q are the same rotation."""
    return bool(np.allclose(a, b, atol=atol) or np.allclose(a, -b, atol=atol))


# --- fixed cases ----------------------------------------------------------------------


def test_identity_quaternion_is_the_identity_matrix():
    assert np.array_equal(quat_to_matrix((0, 0, 0, 1)), np.eye(3))


def test_quarter_turn_about_y_maps_x_to_minus_z():
    q = quat_from_axis_angle((0, 1, 0), math.pi / 2)
    assert np.allclose(rotate(q, (1, 0, 0)), (0, 0, -1))


def test_multiply_applies_right_then_left():
    qx = quat_from_axis_angle((1, 0, 0), 0.3)
    qy = quat_from_axis_angle((0, 1, 0), -1.1)
    v = np.array([0.3, -2.0, 0.7])
    assert np.allclose(rotate(quat_multiply(qy, qx), v), rotate(qy, rotate(qx, v)))


def test_euler_is_x_then_y_then_z():
    q = quat_from_euler_deg((90, 90, 0))
    # X by 90: +Y -> +Z; then Y by 90: +Z -> +X.
    assert np.allclose(rotate(q, (0, 1, 0)), (1, 0, 0))


def test_euler_gimbal_lock_still_round_trips_the_rotation():
    q = quat_from_euler_deg((30.0, 90.0, 40.0))
    back = quat_from_euler_deg(quat_to_euler_deg(q))
    assert np.allclose(quat_to_matrix(q), quat_to_matrix(back), atol=1e-9)


def test_look_at_points_minus_z_at_the_target_with_y_up():
    eye, target = np.array([3.0, 2.0, 5.0]), np.array([-1.0, 0.5, -2.0])
    r = quat_to_matrix(look_at_quat(eye, target))
    forward = r @ np.array([0.0, 0.0, -1.0])
    assert np.allclose(forward, normalize(target - eye))
    right, up = r[:, 0], r[:, 1]
    assert abs(right[1]) < 1e-12  # no roll: the right vector stays horizontal
    assert up[1] > 0
    assert np.allclose(r.T @ r, np.eye(3))
    assert np.isclose(np.linalg.det(r), 1.0)


def test_look_at_straight_down_is_well_defined():
    q = look_at_quat((0, 5, 0), (0, 0, 0))
    assert np.all(np.isfinite(q))
    assert np.allclose(rotate(q, (0, 0, -1)), (0, -1, 0))


def test_normalize_zero_vector_raises():
    with pytest.raises(ValueError):
        normalize((0.0, 0.0, 0.0))


def test_trs_matrix_is_t_r_s():
    q = quat_from_axis_angle((0, 0, 1), math.pi / 2)
    m = trs_matrix((1, 2, 3), q, (2, 3, 4))
    # local +X, scaled by 2, rotated to +Y, then translated.
    assert np.allclose(transform_points(m, np.array([[1.0, 0.0, 0.0]])), [[1.0, 4.0, 3.0]])
    assert np.allclose(transform_vectors(m, np.array([[0.0, 1.0, 0.0]])), [[-3.0, 0.0, 0.0]])


# --- properties ---------------------------------------------------------------------------


@FAST
@given(quats)
def test_quaternion_matrix_round_trip(q):
    m = quat_to_matrix(q)
    assert np.allclose(m.T @ m, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(m), 1.0)
    back = quat_from_matrix(m)
    assert back[3] >= 0
    assert same_rotation(back, q)


@FAST
@given(quats, quats)
def test_multiply_matches_matrix_product(a, b):
    assert np.allclose(quat_to_matrix(quat_multiply(a, b)), quat_to_matrix(a) @ quat_to_matrix(b), atol=1e-12)


@FAST
@given(quats)
def test_conjugate_is_the_inverse(q):
    assert same_rotation(quat_multiply(q, quat_conjugate(q)), np.array([0.0, 0.0, 0.0, 1.0]))


@FAST
@given(st.floats(-179.0, 179.0), st.floats(-89.0, 89.0), st.floats(-179.0, 179.0))
def test_euler_round_trip(ex, ey, ez):
    angles = quat_to_euler_deg(quat_from_euler_deg((ex, ey, ez)))
    assert np.allclose(angles, (ex, ey, ez), atol=1e-6)


@FAST
@given(quats)
def test_matrix_to_euler_to_matrix(q):
    back = quat_from_euler_deg(quat_to_euler_deg(q))
    # quat_to_euler_deg snaps to gimbal lock when |sin(pitch)| > 1 - 1e-9, i.e. within ~4.5e-5 rad
    # of +-90 degrees, so near there the round trip is only that good.
    assert np.allclose(quat_to_matrix(back), quat_to_matrix(q), atol=1e-4)


def test_euler_round_trip_is_tight_away_from_gimbal_lock():
    for pitch in (-89.9, -45.0, 0.0, 30.0, 89.9):
        q = quat_from_euler_deg((12.0, pitch, -70.0))
        back = quat_from_euler_deg(quat_to_euler_deg(q))
        assert np.allclose(quat_to_matrix(back), quat_to_matrix(q), atol=1e-12)


@FAST
@given(vec3s, quats, scales, vec3s)
def test_trs_inverse_inverts(p, q, s, point):
    m, inv = trs_matrix(p, q, s), trs_inverse(p, q, s)
    assert np.allclose(m @ inv, np.eye(4), atol=1e-9 * max(1.0, *map(abs, p)) * 400)
    x = np.array([point])
    assert np.allclose(transform_points(inv, transform_points(m, x)), x, atol=1e-8 * (1 + np.abs(x).max()) * 400)


@FAST
@given(vec3s, vec3s.filter(lambda v: np.linalg.norm(v) > 1e-3))
def test_look_at_property(eye, offset):
    target = np.add(eye, offset)
    q = look_at_quat(eye, target)
    assert np.isclose(np.linalg.norm(q), 1.0)
    assert np.allclose(rotate(q, (0, 0, -1)), normalize(offset), atol=1e-9)
