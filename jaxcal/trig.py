"""sin and cos of joint angles as one vectorisable polynomial (the forward-kinematics hot path).

XLA CPU computes float64 ``sin``/``cos`` one value at a time (a libm-like call per element),
which costs more than the rest of forward kinematics on large batches. :func:`sincos` is plain
arithmetic that XLA fuses and vectorises:

* reduction by pi/2: ``n = round(x 2/pi)``, ``r = ((x - n P1) - n P2) - n P3`` (Cody–Waite),
  with ``P1 + P2 + P3 = pi/2`` split so that ``n P1`` and ``n P2`` are exact (33 significant
  bits each) for ``|n| < 2^20``;
* minimax polynomials on ``|r| <= pi/4`` (fdlibm's ``__kernel_sin``/``__kernel_cos``, Sun
  Microsystems 1993): ``sin r = r + r^3 S(r^2)`` to ``r^13``, ``cos r = 1 - r^2/2 + r^4 C(r^2)`` to
  ``r^14``, truncation error below 2.7e-18 and 1.0e-18 (checked against mpmath);
* the quadrant ``n mod 4`` swaps and negates.

Accuracy (``tests/test_trig.py``, against NumPy): absolute error at most 2.3e-16 for
``|x| <= DOMAIN``, i.e. within 2 units in the last place of values of order one. Joint angles
beyond :data:`DOMAIN` are refused at the entry points (:func:`jaxcal.kinematics.check_q`).
Derivatives are exact by a custom JVP (``d sin = cos dx``, ``d cos = -sin dx``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

DOMAIN = 1e5
"""Largest ``|angle|`` (rad) the reduction is verified for: about 16,000 turns."""

_TWO_OVER_PI = 0.6366197723675814
_P1, _P2, _P3 = 1.5707963267341256, 6.077100506303966e-11, 2.0222662487959506e-21
_S = (
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
)
_C = (
    4.16666666666666019037e-02,
    -1.38888888888741095749e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
)


def _horner(coeffs, x):
    acc = coeffs[-1]
    for c in coeffs[-2::-1]:
        acc = acc * x + c
    return acc


@jax.custom_jvp
def sincos(x: Float[Array, "*b"]) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    """``(sin x, cos x)`` elementwise, float64, for ``|x| <= DOMAIN`` (module docstring)."""
    n = jnp.round(x * _TWO_OVER_PI)
    r = ((x - n * _P1) - n * _P2) - n * _P3
    z = r * r
    s, c = r + (r * z) * _horner(_S, z), (1.0 - 0.5 * z) + (z * z) * _horner(_C, z)
    k = n.astype(jnp.int32) & 3
    odd = (k & 1) == 1
    s, c = jnp.where(odd, c, s), jnp.where(odd, s, c)
    return jnp.where((k & 2) == 2, -s, s), jnp.where(((k + 1) & 2) == 2, -c, c)


@sincos.defjvp
def _sincos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    s, c = sincos(x)
    return (s, c), (c * dx, -s * dx)
