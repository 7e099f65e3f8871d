"""Precision policy: jaxcal runs in float64, always.

Importing :mod:`jaxcal` switches on ``jax_enable_x64``. Every public entry point calls
:func:`as_f64` on the arrays it receives, which

* raises :class:`jaxcal.PrecisionError` if something switched x64 off again after import
  (then ``jnp.asarray`` would silently truncate float64 to float32), and
* upcasts float32/float16/integer inputs to float64 (documented behaviour: a float32 input
  carries only float32 information, but the calibration itself never runs in float32).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .errors import DataError, PrecisionError

jax.config.update("jax_enable_x64", True)


def ensure_x64() -> None:
    """Raise if float64 has been switched off since :mod:`jaxcal` was imported."""
    if not jax.config.jax_enable_x64:
        raise PrecisionError(
            "jax_enable_x64 is off: jaxcal refuses to calibrate in float32. "
            "Do not set JAX_ENABLE_X64=0 or jax.config.update('jax_enable_x64', False) "
            "after importing jaxcal."
        )


def as_f64(x, name: str = "array") -> jax.Array:
    """Return ``x`` as a float64 JAX array (a copy; the caller's array is never touched).

    Raises :class:`DataError` for complex or non-numeric input, :class:`PrecisionError` when
    x64 is disabled. Tracers (inside ``jit``/``vmap``) are passed through after a dtype cast.
    """
    ensure_x64()
    if isinstance(x, jax.core.Tracer):
        return x.astype(jnp.float64)
    arr = np.asarray(x)
    if arr.dtype == object or not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer) or arr.dtype == np.bool_
    ):
        raise DataError(f"{name}: expected real numbers, got dtype {arr.dtype}")
    return jnp.asarray(arr, dtype=jnp.float64)
