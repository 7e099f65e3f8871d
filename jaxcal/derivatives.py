"""Analytic partial derivatives of the link transforms and the error operators Omega
(paper eq. 3-7), written from the closed forms (not autodiff).

Every function takes ``(theta, d, a, alpha)`` broadcastable arrays and returns
``(..., 4, 4, 4)``: entry ``[..., k, :, :]`` belongs to parameter ``p_k`` in the order
``(theta, d, a, alpha)``.

* ``*_partials``: ``dA/dp_k``.
* ``*_omegas``: ``Omega_k = A^{-1} dA/dp_k`` (right-multiplied, the paper's eq. 5), so that
  ``dA = A (sum_k Omega_k dp_k)``.
* ``*_left_omegas``: ``dA/dp_k A^{-1}`` (left-multiplied).
* ``*_omega_twists``: ``vee(Omega_k)`` as ``(..., 4, 6)`` twists ``[v, w]``.

The paper prints several of these with sign/factor typos; ``docs/errata.md`` lists them and
``tests/test_derivatives_autodiff.py`` proves the correct forms against ``jax.jacfwd``.

What holds (checked in the tests): the right-multiplied SDH Omegas do not depend on theta
(the paper's claim); the right-multiplied MDH Omegas do (through ``a`` and ``alpha``); for
left-multiplied errors it is the other way round: SDH's depend on theta, MDH's do not.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float


def _prep(theta, d, a, alpha):
    theta, d, a, alpha = jnp.broadcast_arrays(*(jnp.asarray(x, jnp.float64) for x in (theta, d, a, alpha)))
    return theta, d, a, alpha, jnp.zeros_like(theta), jnp.ones_like(theta)


def _mat(rows):
    return jnp.stack([jnp.stack(r, -1) for r in rows], -2)


def _stack4(*ms):
    return jnp.stack(ms, -3)


def sdh_partials(theta, d, a, alpha) -> Float[Array, "*b 4 4 4"]:
    """``dA/d(theta, d, a, alpha)`` of the SDH link, paper eq. (4) (printed correctly)."""
    theta, d, a, alpha, z, o = _prep(theta, d, a, alpha)
    ct, st, ca, sa = jnp.cos(theta), jnp.sin(theta), jnp.cos(alpha), jnp.sin(alpha)
    dth = _mat([(-st, -ca * ct, sa * ct, -a * st), (ct, -ca * st, sa * st, a * ct), (z, z, z, z), (z, z, z, z)])
    dd = _mat([(z, z, z, z), (z, z, z, z), (z, z, z, o), (z, z, z, z)])
    da = _mat([(z, z, z, ct), (z, z, z, st), (z, z, z, z), (z, z, z, z)])
    dal = _mat([(z, st * sa, st * ca, z), (z, -ct * sa, -ct * ca, z), (z, ca, -sa, z), (z, z, z, z)])
    return _stack4(dth, dd, da, dal)


def sdh_omegas(theta, d, a, alpha) -> Float[Array, "*b 4 4 4"]:
    """SDH error operators ``Omega_k = A^{-1} dA/dp_k``, paper eq. (5).

    Independent of theta. Erratum: the paper's combined ``Omega_i`` has the signs of its
    ``Delta alpha`` entries (2,3) and (3,2) swapped; the separate ``Omega_alpha`` is right.
    """
    theta, d, a, alpha, z, o = _prep(theta, d, a, alpha)
    ca, sa = jnp.cos(alpha), jnp.sin(alpha)
    om_th = _mat([(z, -ca, sa, z), (ca, z, z, a * ca), (-sa, z, z, -a * sa), (z, z, z, z)])
    om_d = _mat([(z, z, z, z), (z, z, z, sa), (z, z, z, ca), (z, z, z, z)])
    om_a = _mat([(z, z, z, o), (z, z, z, z), (z, z, z, z), (z, z, z, z)])
    om_al = _mat([(z, z, z, z), (z, z, -o, z), (z, o, z, z), (z, z, z, z)])
    return _stack4(om_th, om_d, om_a, om_al)


def sdh_left_omegas(theta, d, a, alpha) -> Float[Array, "*b 4 4 4"]:
    """SDH left-multiplied operators ``dA/dp_k A^{-1}`` (depend on theta through a, alpha)."""
    theta, d, a, alpha, z, o = _prep(theta, d, a, alpha)
    ct, st = jnp.cos(theta), jnp.sin(theta)
    l_th = _mat([(z, -o, z, z), (o, z, z, z), (z, z, z, z), (z, z, z, z)])
    l_d = _mat([(z, z, z, z), (z, z, z, z), (z, z, z, o), (z, z, z, z)])
    l_a = _mat([(z, z, z, ct), (z, z, z, st), (z, z, z, z), (z, z, z, z)])
    # rotation about the new x axis (ct, st, 0) through the point (0, 0, d)
    l_al = _mat([(z, z, st, -st * d), (z, z, -ct, ct * d), (-st, ct, z, z), (z, z, z, z)])
    return _stack4(l_th, l_d, l_a, l_al)


def mdh_partials(theta, d, a, alpha) -> Float[Array, "*b 4 4 4"]:
    """``dA/d(theta, d, a, alpha)`` of the MDH link, paper eq. (6), corrected.

    Erratum in the paper's ``dA/dtheta``: entry (1,2) is ``-c theta`` (printed ``-c alpha
    c theta``), row 3 is ``(s alpha c theta, -s alpha s theta, 0, 0)`` (printed ``(s alpha
    s theta, -s alpha c theta, 0, 0)``).
    """
    theta, d, a, alpha, z, o = _prep(theta, d, a, alpha)
    ct, st, ca, sa = jnp.cos(theta), jnp.sin(theta), jnp.cos(alpha), jnp.sin(alpha)
    dth = _mat([(-st, -ct, z, z), (ca * ct, -ca * st, z, z), (sa * ct, -sa * st, z, z), (z, z, z, z)])
    dd = _mat([(z, z, z, z), (z, z, z, -sa), (z, z, z, ca), (z, z, z, z)])
    da = _mat([(z, z, z, o), (z, z, z, z), (z, z, z, z), (z, z, z, z)])
    dal = _mat([(z, z, z, z), (-st * sa, -ct * sa, -ca, -d * ca), (st * ca, ct * ca, -sa, -d * sa), (z, z, z, z)])
    return _stack4(dth, dd, da, dal)


def mdh_omegas(theta, d, a, alpha) -> Float[Array, "*b 4 4 4"]:
    """MDH error operators ``Omega_k = A^{-1} dA/dp_k``, paper eq. (7), corrected.

    Depend on theta (through the a and alpha operators). Errata in the paper's combined
    ``Omega_i``: (1,2) is ``-Delta theta`` (printed ``-c alpha Delta theta``), (1,3) is
    ``-s theta Delta alpha`` (printed ``s alpha Delta theta``), (3,1) is ``s theta Delta alpha``
    (printed ``s theta Delta theta``).
    """
    theta, d, a, alpha, z, o = _prep(theta, d, a, alpha)
    ct, st = jnp.cos(theta), jnp.sin(theta)
    om_th = _mat([(z, -o, z, z), (o, z, z, z), (z, z, z, z), (z, z, z, z)])
    om_d = _mat([(z, z, z, z), (z, z, z, z), (z, z, z, o), (z, z, z, z)])
    om_a = _mat([(z, z, z, ct), (z, z, z, -st), (z, z, z, z), (z, z, z, z)])
    om_al = _mat([(z, z, -st, -d * st), (z, z, -ct, -d * ct), (st, ct, z, z), (z, z, z, z)])
    return _stack4(om_th, om_d, om_a, om_al)


def mdh_left_omegas(theta, d, a, alpha) -> Float[Array, "*b 4 4 4"]:
    """MDH left-multiplied operators ``dA/dp_k A^{-1}`` (independent of theta)."""
    theta, d, a, alpha, z, o = _prep(theta, d, a, alpha)
    ca, sa = jnp.cos(alpha), jnp.sin(alpha)
    # rotation about the axis (0, -sa, ca) through the point (a, 0, 0)
    l_th = _mat([(z, -ca, -sa, z), (ca, z, z, -a * ca), (sa, z, z, -a * sa), (z, z, z, z)])
    l_d = _mat([(z, z, z, z), (z, z, z, -sa), (z, z, z, ca), (z, z, z, z)])
    l_a = _mat([(z, z, z, o), (z, z, z, z), (z, z, z, z), (z, z, z, z)])
    l_al = _mat([(z, z, z, z), (z, z, -o, z), (z, o, z, z), (z, z, z, z)])
    return _stack4(l_th, l_d, l_a, l_al)


def _vee(m):
    return jnp.stack([m[..., 0, 3], m[..., 1, 3], m[..., 2, 3], m[..., 2, 1], m[..., 0, 2], m[..., 1, 0]], -1)


def sdh_omega_twists(theta, d, a, alpha) -> Float[Array, "*b 4 6"]:
    """``vee(Omega_k)`` for the SDH link, as twists ``[v, w]`` in the link's own frame."""
    return _vee(sdh_omegas(theta, d, a, alpha))


def mdh_omega_twists(theta, d, a, alpha) -> Float[Array, "*b 4 6"]:
    """``vee(Omega_k)`` for the MDH link, as twists ``[v, w]`` in the link's own frame."""
    return _vee(mdh_omegas(theta, d, a, alpha))


PARTIALS = {"sdh": sdh_partials, "mdh": mdh_partials}
OMEGAS = {"sdh": sdh_omegas, "mdh": mdh_omegas}
OMEGA_TWISTS = {"sdh": sdh_omega_twists, "mdh": mdh_omega_twists}


def omega_twist_entries(convention: str, c, s, d, a, alpha) -> list:
    """Closed form of :data:`OMEGA_TWISTS` entry by entry, for the structure-of-arrays
    Jacobian (:func:`jaxcal.error_model.identification_jacobian`): for ``k = theta, d, a,
    alpha`` a pair ``(v, w)`` of 3-lists whose entries are arrays (broadcast from cos/sin of
    theta ``c, s``, ``d`` and ``a, alpha``), the Python float ``1.0``, or ``0.0`` for a
    structural zero (:func:`jaxcal.kinematics.is_zero`), so callers skip the arithmetic they
    do not need.

    SDH (eq. 5): ``Omega_theta`` is a rotation about ``(0, s alpha, c alpha)`` with
    ``v = (0, a c alpha, -a s alpha)``; ``Omega_d`` a translation along ``(0, s alpha, c alpha)``;
    ``Omega_a`` along x; ``Omega_alpha`` a rotation about x. MDH (eq. 7, corrected): rotation
    about z; translation along z; translation along ``(c theta, -s theta, 0)``; rotation about
    that axis with ``v = (-d s theta, -d c theta, 0)``.
    """
    zero = [0.0, 0.0, 0.0]
    if convention == "sdh":
        ca, sa = jnp.cos(alpha), jnp.sin(alpha)
        return [
            ([0.0, a * ca, -a * sa], [0.0, sa, ca]),
            ([0.0, sa, ca], zero),
            ([1.0, 0.0, 0.0], zero),
            (zero, [1.0, 0.0, 0.0]),
        ]
    return [
        (zero, [0.0, 0.0, 1.0]),
        ([0.0, 0.0, 1.0], zero),
        ([c, -s, 0.0], zero),
        ([-d * s, -d * c, 0.0], [c, -s, 0.0]),
    ]
