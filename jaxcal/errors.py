"""Typed errors raised by jaxcal's public entry points."""


class JaxcalError(Exception):
    """Base class of every error jaxcal raises on purpose."""


class DataError(JaxcalError, ValueError):
    """Bad measurement or array input: the message names the row, column or parameter."""


class RobotFileError(JaxcalError, ValueError):
    """A robot description (TOML or constructor arguments) is malformed."""


class PrecisionError(JaxcalError, RuntimeError):
    """float64 is not available (``jax_enable_x64`` was switched off)."""
