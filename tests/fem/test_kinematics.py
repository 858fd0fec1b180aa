"""Tensor algebra of the TLED kernels: the 3x3 symmetric eigen-decomposition used by stretch-based laws."""
import numpy as np
import pytest

from tissuemech.fem.kinematics import symmetric_eigen3


def _decompose(b):
    out = symmetric_eigen3(b[0, 0], b[1, 1], b[2, 2], b[0, 1], b[1, 2], b[0, 2])
    return np.array(out[:3]), np.array(out[3:]).reshape(3, 3).T  # columns are eigenvectors


@pytest.mark.parametrize("scale", [0.5, 0.05, 1e-4, 1e-9])
def test_random_left_cauchy_green_tensors_are_decomposed_to_rounding(scale):
    rng = np.random.default_rng(7)
    for _ in range(500):
        F = np.eye(3) + scale * rng.standard_normal((3, 3))
        b = F @ F.T
        lam, V = _decompose(b)
        np.testing.assert_allclose(V @ np.diag(lam) @ V.T, b, rtol=0, atol=4e-15 * np.abs(b).max())
        np.testing.assert_allclose(V.T @ V, np.eye(3), rtol=0, atol=4e-15)
        np.testing.assert_allclose(np.sort(lam), np.linalg.eigvalsh(b), rtol=0, atol=4e-15 * np.abs(b).max())


@pytest.mark.parametrize("b", [np.eye(3), np.diag([1.0, 1.0, 2.0]), np.diag([0.5, 2.0, 2.0]),
                               np.array([[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 3.0]]),  # 1, 3, 3
                               np.array([[1.0, 1e-13, 0.0], [1e-13, 1.0, 0.0], [0.0, 0.0, 1.0]])])
def test_repeated_eigenvalues_give_an_orthonormal_basis(b):
    lam, V = _decompose(b)
    np.testing.assert_allclose(V @ np.diag(lam) @ V.T, b, atol=1e-14)
    np.testing.assert_allclose(V.T @ V, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(np.sort(lam), np.linalg.eigvalsh(b), atol=1e-14)
