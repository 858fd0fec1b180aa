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


@pytest.mark.parametrize("relative_gap", [1e-8, 1e-3, 0.049, 0.051, 0.2, 0.5])
def test_known_eigenvectors_are_recovered_on_both_sides_of_the_closed_form_gap(relative_gap):
    # A = Q diag(lam) Q^T with a random rotation Q: the oracle is the construction, not a solver. The smallest
    # gap is relative_gap of the spread, below and above CLOSED_FORM_MIN_GAP (0.05), where symmetric_eigen3
    # switches between Jacobi rotations and the closed form
    from tissuemech.fem.kinematics import CLOSED_FORM_MIN_GAP, jacobi_eigen3
    assert 0.049 < CLOSED_FORM_MIN_GAP < 0.051
    rng = np.random.default_rng(3)
    n_rotations = 0
    for _ in range(200):
        Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
        spread = 10.0 ** rng.uniform(-6, 0)
        lam = 1.0 + spread * np.array([1.0, relative_gap, 0.0])
        b = Q @ np.diag(lam) @ Q.T
        b = 0.5 * (b + b.T)
        got, V = _decompose(b)
        order = np.argsort(-got)
        np.testing.assert_allclose(got[order], np.sort(lam)[::-1], rtol=0, atol=4e-15 * lam.max())
        np.testing.assert_allclose(V.T @ V, np.eye(3), rtol=0, atol=4e-15)
        np.testing.assert_allclose(V @ np.diag(got) @ V.T, b, rtol=0, atol=4e-15)
        # the eigenvector of the isolated largest eigenvalue, to within the conditioning of the problem
        # (input rounding eps |A| over the gap to the next eigenvalue)
        q1 = Q[:, 0]
        v1 = V[:, order[0]]
        gap = spread * (1.0 - relative_gap)
        assert np.linalg.norm(np.cross(v1, q1)) < 1e-15 + 20 * 2.2e-16 * lam.max() / gap  # sine of the angle
        same = got.tolist() == list(jacobi_eigen3(b[0, 0], b[1, 1], b[2, 2], b[0, 1], b[1, 2], b[0, 2])[:3])
        n_rotations += same
        if relative_gap < CLOSED_FORM_MIN_GAP:  # the rotations' result, exactly
            assert same
    if relative_gap > CLOSED_FORM_MIN_GAP:  # the closed form ran (its last bits differ from the rotations')
        assert n_rotations < 150


def test_the_closed_form_is_faster_path_for_well_separated_eigenvalues_and_agrees_with_jacobi():
    # the Ogden stress sum_k d_k n_k n_k from both decompositions of the same tensors, to rounding
    from tissuemech.fem.kinematics import jacobi_eigen3
    rng = np.random.default_rng(11)
    worst = 0.0
    for _ in range(2000):
        F = np.eye(3) + 0.1 * rng.standard_normal((3, 3))
        b = F @ F.T
        args = (b[0, 0], b[1, 1], b[2, 2], b[0, 1], b[1, 2], b[0, 2])
        stresses = []
        for decompose in (symmetric_eigen3, jacobi_eigen3):
            out = decompose(*args)
            lam, V = np.array(out[:3]), np.array(out[3:]).reshape(3, 3).T
            beta = lam ** -2.5  # beta_k = lambda_k^(alpha/2) of a one-term Ogden law with alpha = -5
            d = beta - beta.mean()
            stresses.append(V @ np.diag(d) @ V.T)
        worst = max(worst, np.abs(stresses[0] - stresses[1]).max() / np.abs(stresses[1]).max())
    assert worst < 1e-13
