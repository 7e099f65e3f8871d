"""sin and cos of joint angles as one vectorisable polynomial (the forward-kinematics hot path).

XLA CPU computes float64 ``sin``/``cos`` one value at a time (a libm-like call per element):
for 1e5 poses x 6 joints they took longer than the whole rest of forward kinematics
(``benchmarks/bench_roofline.py``). :func:`sincos` is plain arithmetic that XLA fuses and
vectorises:

* reduction by pi/2: ``n = round(x 2/pi)``, ``r = ((x - n P1) - n P2) - n P3`` (Cody–Waite),
  with ``P1 + P2 + P3 = pi/2`` split so that ``n P1`` and ``n P2`` are exact (33 significant
  bits each) for ``|n| < 2^20``;
* Taylor series on ``|r| <= pi/4``: sin to ``r^17``, cos to ``r^18`` (the first omitted terms are
  below 1e-19);
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
_SIN = (1.0, -1 / 6, 1 / 120, -1 / 5040, 1 / 362880, -1 / 39916800, 1 / 6227020800,
        -1 / 1307674368000, 1 / 355687428096000)  # (-1)^k / (2k+1)!
_COS = (1.0, -1 / 2, 1 / 24, -1 / 720, 1 / 40320, -1 / 3628800, 1 / 479001600,
        -1 / 87178291200, 1 / 20922789888000, -1 / 6402373705728000)  # (-1)^k / (2k)!


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
    r2 = r * r
    s, c = r * _horner(_SIN, r2), _horner(_COS, r2)
    k = n.astype(jnp.int32) & 3
    odd = (k & 1) == 1
    s, c = jnp.where(odd, c, s), jnp.where(odd, s, c)
    return jnp.where((k & 2) == 2, -s, s), jnp.where(((k + 1) & 2) == 2, -c, c)


@sincos.defjvp
def _sincos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    s, c = sincos(x)
    return (s, c), (c * dx, -s * dx)
