import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcal
from jaxcal._config import as_f64


def test_x64_enabled_by_import():
    assert jax.config.jax_enable_x64
    assert jaxcal.fk(jaxcal.preset("paper-6r"), jnp.zeros(6)).dtype == jnp.float64


def test_float32_input_is_upcast_not_truncated():
    x = np.array([0.1, 0.2], np.float32)
    y = as_f64(x)
    assert y.dtype == jnp.float64
    r = jaxcal.Robot(np.zeros((2, 4), np.float32))
    assert r.dh.dtype == jnp.float64


def test_refuses_when_x64_switched_off():
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(jaxcal.PrecisionError, match="float32"):
            as_f64(np.zeros(3))
        with pytest.raises(jaxcal.PrecisionError, match="float32"):  # not XLA's dtype error from inside jit
            jaxcal.fk(jaxcal.preset("ur5"), np.zeros(6))
    finally:
        jax.config.update("jax_enable_x64", True)


def test_rejects_non_numeric():
    with pytest.raises(jaxcal.DataError, match="dh"):
        jaxcal.Robot(np.array([["a", "b", "c", "d"]]))
