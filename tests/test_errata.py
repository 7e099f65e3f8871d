"""The paper's printed matrices against autodiff: the correct entries agree, and exactly the
entries listed in docs/errata.md disagree. A test per erratum."""

import jax
import jax.numpy as jnp
import numpy as np
import paper_printed as PP
import pytest
from numpy.testing import assert_allclose

from jaxcal import derivatives as D
from jaxcal import kinematics as K
from jaxcal.lie import inv_transform

# a generic point: no accidental zeros or equalities
P = (0.7, 123.0, 321.0, -0.4)
DELTA = (1e-3, 2e-2, -3e-2, 4e-3)  # (dtheta, dd, da, dalpha)


def _ad(conv, p=P):
    return np.moveaxis(np.asarray(jax.jacfwd(lambda x: K.LINKS[conv](*x))(jnp.array(p))), -1, 0)


def _wrong_entries(printed, truth, tol=1e-9):
    return {(int(i) + 1, int(j) + 1) for i, j in zip(*np.nonzero(np.abs(printed - truth) > tol))}


def test_eq4_sdh_partials_as_printed_are_correct():
    for printed, truth in zip(PP.sdh_dA(*P), _ad("sdh")):
        assert_allclose(printed, truth, atol=1e-12)


def test_eq5_sdh_omega_parts_as_printed_are_correct():
    A = np.asarray(K.sdh_link(*P))
    for printed, truth in zip(PP.sdh_omega_parts(*P), np.linalg.solve(A, _ad("sdh"))):
        assert_allclose(printed, truth, atol=1e-12)


def test_eq5_sdh_combined_omega_erratum():
    """Erratum E1: combined Omega_i, entries (2,3) and (3,2) have the sign of Delta alpha
    flipped."""
    truth = np.einsum("kij,k->ij", np.asarray(D.sdh_omegas(*P)), DELTA)
    A = np.asarray(K.sdh_link(*P))
    assert_allclose(truth, np.einsum("kij,k->ij", np.linalg.solve(A, _ad("sdh")), DELTA), atol=1e-12)
    printed = PP.sdh_omega_combined(*P, *DELTA)
    assert _wrong_entries(printed, truth) == {(2, 3), (3, 2)}
    assert printed[1, 2] == pytest.approx(-truth[1, 2]) and printed[2, 1] == pytest.approx(-truth[2, 1])


def test_eq6_mdh_partials_erratum():
    """Erratum E2: MDH dA/dtheta, entries (1,2), (3,1), (3,2) are wrong; dA/dd, dA/da,
    dA/dalpha are printed correctly."""
    printed, truth = PP.mdh_dA(*P), _ad("mdh")
    assert _wrong_entries(printed[0], truth[0]) == {(1, 2), (3, 1), (3, 2)}
    for k in (1, 2, 3):
        assert_allclose(printed[k], truth[k], atol=1e-12)
    assert_allclose(np.asarray(D.mdh_partials(*P)), truth, atol=1e-12)


def test_eq7_mdh_combined_omega_erratum():
    """Erratum E3: MDH combined Omega_i, entries (1,2), (1,3), (3,1) are wrong."""
    A = np.asarray(K.mdh_link(*P))
    truth = np.einsum("kij,k->ij", np.linalg.solve(A, _ad("mdh")), DELTA)
    printed = PP.mdh_omega_combined(*P, *DELTA)
    assert _wrong_entries(printed, truth) == {(1, 2), (1, 3), (3, 1)}
    assert_allclose(np.einsum("kij,k->ij", np.asarray(D.mdh_omegas(*P)), DELTA), truth, atol=1e-12)


def test_eq8_first_term_is_dA1_not_A1():
    """Erratum E4: eq. (8) prints dT_1 = A_1; the differential of T_1 = A_1 is dA_1."""
    dA1 = np.einsum("kij,k->ij", _ad("sdh"), DELTA)
    A1 = np.asarray(K.sdh_link(*P))
    Ap = np.asarray(K.sdh_link(*(np.array(P) + 1e-4 * np.array(DELTA))))
    first_order = (Ap - A1) / 1e-4
    assert_allclose(first_order, dA1, atol=1e-3)
    assert np.abs(first_order - A1).max() > 1.0


def test_eq10_intermediate_step_erratum():
    """Erratum E5: eq. (10) writes dT_{n-1} A_n T_n^{-1} = dT_{n-1} T_n^{-1}; the correct
    right-hand side is dT_{n-1} T_{n-1}^{-1} (the final sum is right)."""
    rng = np.random.default_rng(3)
    dT_prev = rng.normal(size=(4, 4))
    T_prev = np.asarray(K.sdh_link(*P)) @ np.asarray(K.sdh_link(0.3, 10.0, 50.0, 1.0))
    A_n = np.asarray(K.sdh_link(-0.2, 40.0, 70.0, -1.2))
    T_n = T_prev @ A_n
    lhs = dT_prev @ A_n @ np.asarray(inv_transform(jnp.asarray(T_n)))
    assert_allclose(lhs, dT_prev @ np.linalg.inv(T_prev), atol=1e-12)
    assert np.abs(lhs - dT_prev @ np.linalg.inv(T_n)).max() > 1e-3


def test_eq13_w6_translation_erratum():
    """Erratum E6: eq. (13)'s simplified translation entries of W_6 = T_6 Omega_6 T_6^{-1}
    (alpha_6 = 0) carry three sign slips: in (1,4) the Delta theta coefficient's f34 f23, in
    (2,4) and (3,4) the Delta alpha coefficients' f34 f11 and f24 f11. The rotation entries are
    right. Truth: jaxcal's operator (checked against autodiff above) conjugated by T_6."""
    q = np.array([0.4, -1.1, 0.7, 1.9, -0.6, 0.8])
    dh = np.array([[0, 0, 160, -np.pi / 2], [-np.pi / 2, 0, 580, 0], [0, 0, 200, -np.pi / 2]])
    dh = np.r_[dh, [[0, 640, 0, np.pi / 2], [0, 228, 0, -np.pi / 2], [0, 50, 37.0, 0]]]  # a_6, d_6 != 0
    F = np.eye(4)
    for (th, d, a, al), qi in zip(dh, q):
        F = F @ np.asarray(K.sdh_link(th + qi, d, a, al))
    dth, dd, da, dal = DELTA
    omega = np.einsum("kij,k->ij", np.asarray(D.sdh_omegas(dh[5, 0] + q[5], *dh[5, 1:])), DELTA)
    truth = F @ omega @ np.linalg.inv(F)
    printed = PP.eq13_w6(F, dh[5, 2], dth, dd, da, dal)
    assert _wrong_entries(printed, truth) == {(1, 4), (2, 4), (3, 4)}
    f = lambda i, j: F[i - 1, j - 1]  # noqa: E731
    fixed = printed.copy()  # the three coefficients with their sign corrected
    fixed[0, 3] -= 2 * f(3, 4) * f(2, 3) * dth
    fixed[1, 3] += 2 * f(3, 4) * f(1, 1) * dal
    fixed[2, 3] -= 2 * f(2, 4) * f(1, 1) * dal
    assert_allclose(fixed, truth, atol=1e-12)
