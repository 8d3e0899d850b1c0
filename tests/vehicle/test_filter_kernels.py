"""``testbed.vehicle.filter_kernels``: the compiled filter arithmetic against numpy's own
matrix products and LAPACK inverse (a second method), on random covariances."""

from __future__ import annotations

import math

import numpy as np
import pytest

from testbed.common.geometry import quat_normalize, rotation_matrix
from testbed.vehicle.filter_kernels import (
    APPLIED,
    GATED,
    SINGULAR,
    gated_update,
    propagate,
)


def _covariance(rng: np.random.Generator) -> np.ndarray:
    a = rng.normal(size=(6, 6))
    return a @ a.T + 0.1 * np.eye(6)


def _observations(rng: np.random.Generator) -> list[np.ndarray]:
    """A depth row, a position block and a rotated velocity block (the filter's three H)."""
    depth = np.array([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]])
    position = np.hstack([np.eye(3), np.zeros((3, 3))])
    velocity = np.zeros((3, 6))
    q = quat_normalize(tuple(rng.normal(size=4)))
    velocity[:, 3:] = np.array(rotation_matrix(q)).T
    return [depth, position, velocity]


def test_propagate_is_f_x_plus_g_u_and_f_p_ft_plus_q() -> None:
    rng = np.random.default_rng(1)
    for _ in range(200):
        x, p = rng.normal(size=6), _covariance(rng)
        f, g, q = rng.normal(size=(6, 6)), rng.normal(size=(6, 3)), _covariance(rng)
        u = rng.normal(size=3)
        x1, p1 = propagate(x, p, f, g, q, u)
        np.testing.assert_allclose(x1, f @ x + g @ u, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(p1, f @ p @ f.T + q, rtol=1e-12, atol=1e-12)
        x0, _ = propagate(x, p, f, g, q, np.zeros(0))
        np.testing.assert_allclose(x0, f @ x, rtol=1e-12, atol=1e-12)


def test_gated_update_is_the_joseph_update_of_numpys_inverse() -> None:
    rng = np.random.default_rng(2)
    for _ in range(200):
        for h in _observations(rng):
            m = h.shape[0]
            x, p = rng.normal(size=6), _covariance(rng)
            z, sigma = rng.normal(size=m), rng.uniform(0.01, 1.0, size=m)
            r = np.diag(sigma**2)
            y = z - h @ x
            s = h @ p @ h.T + r
            k = p @ h.T @ np.linalg.inv(s)
            a = np.eye(6) - k @ h
            x1, p1, nis, status = gated_update(x, p, h, z, sigma, math.inf)
            assert status == APPLIED
            assert nis == pytest.approx(float(y @ np.linalg.solve(s, y)), rel=1e-9)
            np.testing.assert_allclose(x1, x + k @ y, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(p1, a @ p @ a.T + k @ r @ k.T, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(p1, p1.T, rtol=0, atol=1e-12 * np.abs(p1).max())


def test_a_gated_or_singular_update_changes_nothing() -> None:
    rng = np.random.default_rng(3)
    x, p = rng.normal(size=6), _covariance(rng)
    h = np.hstack([np.eye(3), np.zeros((3, 3))])
    z, sigma = x[:3] + 100.0, np.full(3, 0.1)  # far outside any gate
    x1, p1, nis, status = gated_update(x, p, h, z, sigma, 16.0)
    assert status == GATED and nis > 16.0
    assert np.array_equal(x1, x) and np.array_equal(p1, p)
    # no information in the row and no noise: S = 0 cannot be inverted
    x1, p1, nis, status = gated_update(x, p, np.zeros((1, 6)), np.zeros(1), np.zeros(1), 16.0)
    assert status == SINGULAR and math.isnan(nis)
    assert np.array_equal(x1, x) and np.array_equal(p1, p)
