"""Every analytic matrix of eq. 3-7 against jax.jacfwd of the link transform (eq. 1)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from jaxcal import derivatives as D
from jaxcal import kinematics as K

CONVS = ["sdh", "mdh"]
LEFT = {"sdh": D.sdh_left_omegas, "mdh": D.mdh_left_omegas}


def _autodiff_partials(conv):
    link = K.LINKS[conv]

    def f(p):
        # jacfwd puts the differentiated axis last: (4, 4, 4) -> move to front
        return jnp.moveaxis(jax.jacfwd(lambda x: link(*x))(p), -1, 0)

    return jax.jit(jax.vmap(f))


AD = {c: _autodiff_partials(c) for c in CONVS}


def _points(rng, n=400):
    """Generic points plus the special values the paper assumes (alpha in {0, +-pi/2}),
    and near-singular ones (theta, alpha near 0, pi; a, d = 0)."""
    th = rng.uniform(-2 * np.pi, 2 * np.pi, n)
    d = rng.uniform(-800, 800, n)
    a = rng.uniform(-800, 800, n)
    al = rng.uniform(-2 * np.pi, 2 * np.pi, n)
    special = np.array([0.0, np.pi / 2, -np.pi / 2, np.pi, 1e-12, np.pi - 1e-12, -1e-9])
    al[: 3 * len(special)] = np.tile(special, 3)
    th[len(special) : 2 * len(special)] = special
    a[::11] = 0.0
    d[::13] = 0.0
    return np.stack([th, d, a, al], -1)


@pytest.mark.parametrize("conv", CONVS)
def test_partials_match_jacfwd(conv, rng):
    P = _points(rng)
    ad = np.asarray(AD[conv](jnp.asarray(P)))
    an = np.asarray(D.PARTIALS[conv](*P.T))
    assert an.shape == (len(P), 4, 4, 4)
    assert_allclose(an, ad, atol=1e-12, rtol=0)


@pytest.mark.parametrize("conv", CONVS)
def test_right_omegas_match_jacfwd(conv, rng):
    P = _points(rng)
    A = np.asarray(K.LINKS[conv](*P.T))
    ad = np.linalg.solve(A[:, None], np.asarray(AD[conv](jnp.asarray(P))))  # A^-1 dA/dp
    assert_allclose(np.asarray(D.OMEGAS[conv](*P.T)), ad, atol=1e-9, rtol=0)


@pytest.mark.parametrize("conv", CONVS)
def test_left_omegas_match_jacfwd(conv, rng):
    P = _points(rng)
    Ainv = np.linalg.inv(np.asarray(K.LINKS[conv](*P.T)))
    ad = np.asarray(AD[conv](jnp.asarray(P))) @ Ainv[:, None]  # dA/dp A^-1
    assert_allclose(np.asarray(LEFT[conv](*P.T)), ad, atol=1e-9, rtol=0)


@pytest.mark.parametrize("conv", CONVS)
def test_omega_twists_are_vee_of_omegas(conv, rng):
    P = _points(rng, 50)
    tw = np.asarray(D.OMEGA_TWISTS[conv](*P.T))
    om = np.asarray(D.OMEGAS[conv](*P.T))
    # each Omega is in se(3): antisymmetric 3x3 block, zero bottom row
    assert_allclose(om[..., :3, :3], -np.swapaxes(om[..., :3, :3], -1, -2), atol=1e-15)
    assert_allclose(om[..., 3, :], 0.0)
    assert_allclose(tw[..., :3], om[..., :3, 3])
    assert_allclose(tw[..., 3:], np.stack([om[..., 2, 1], om[..., 0, 2], om[..., 1, 0]], -1))


@settings(max_examples=50, deadline=None)
@given(
    st.floats(-7, 7),
    st.floats(-1e3, 1e3),
    st.floats(-1e3, 1e3),
    st.sampled_from([0.0, np.pi / 2, -np.pi / 2, np.pi]) | st.floats(-7, 7),
)
def test_partials_hypothesis(theta, d, a, alpha):
    P = np.array([[theta, d, a, alpha]])
    for conv in CONVS:
        assert_allclose(np.asarray(D.PARTIALS[conv](*P.T)), np.asarray(AD[conv](jnp.asarray(P))), atol=1e-11)


def _theta_derivative(fn, P):
    """d/dtheta of an operator-valued function, by autodiff."""
    g = jax.vmap(lambda p: jax.jacfwd(lambda th: fn(th, p[1], p[2], p[3]))(p[0]))
    return np.asarray(g(jnp.asarray(P)))


def test_which_omegas_depend_on_theta(rng):
    """The paper's claim (SDH Omega independent of theta, MDH not), for right- and left-
    multiplied errors. What holds: right SDH: independent; right MDH: depends (a, alpha
    parts); left SDH: depends (a, alpha parts); left MDH: independent."""
    P = _points(rng, 200)
    P = P[np.abs(np.sin(P[:, 3])) > 0.1]  # generic alpha (at alpha=0 some parts vanish)
    P = P[np.abs(P[:, 1]) > 1.0]
    dep = lambda fn: np.abs(_theta_derivative(fn, P)).max(axis=(0, 2, 3))  # per parameter k
    assert_allclose(dep(D.sdh_omegas), 0.0, atol=1e-14)
    assert_allclose(dep(D.mdh_left_omegas), 0.0, atol=1e-14)
    m_right = dep(D.mdh_omegas)
    s_left = dep(D.sdh_left_omegas)
    # theta and d operators are theta-free in both; a and alpha operators are not
    assert_allclose(m_right[:2], 0.0, atol=1e-14)
    assert np.all(m_right[2:] > 0.5)
    assert_allclose(s_left[:2], 0.0, atol=1e-14)
    assert np.all(s_left[2:] > 0.5)


def _dense_twists(conv, c, s, d, a, al):
    """omega_twist_entries as dense (4, 3, K) arrays V, W (structural 0.0 / 1.0 broadcast)."""
    o = np.ones(np.shape(c))
    dense = lambda e: o * np.asarray(e)
    ent = D.omega_twist_entries(conv, c, s, d, a, al)
    return tuple(np.stack([np.stack([dense(e) for e in vw[j]]) for vw in ent]) for j in (0, 1))


@pytest.mark.parametrize("conv", CONVS)
def test_omega_twist_closed_form_matches_vee_of_omegas(conv, rng):
    """The pose-axis-last closed form used by the structure-of-arrays Jacobian, one link
    (scalar a, alpha) at a time as in the loop over links."""
    P = _points(rng, 50)
    for a, al in [(P[0, 2], P[0, 3]), (0.0, np.pi / 2), (120.0, -np.pi / 2)]:
        Pl = P.copy()
        Pl[:, 2], Pl[:, 3] = a, al
        want = np.asarray(D.OMEGA_TWISTS[conv](*Pl.T))  # (50, 4, 6)
        th, d = jnp.asarray(Pl[:, 0]), jnp.asarray(Pl[:, 1])
        V, W = _dense_twists(conv, jnp.cos(th), jnp.sin(th), d, a, al)  # (4, 3, 50)
        got = np.concatenate([np.asarray(V), np.asarray(W)], 1).transpose(2, 0, 1)
        assert_allclose(got, want, atol=1e-12, rtol=0)
