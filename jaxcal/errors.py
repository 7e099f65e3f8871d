"""Typed errors raised by jaxcal's public entry points."""


class JaxcalError(Exception):
    """Base class of every error jaxcal raises on purpose.

    ``option`` names the argument the message is about (``"folds"``, ``"length_unit"``), so a
    front end can say it in its own words (the CLI prints ``--folds``).
    """

    def __init__(self, message: str, *, option: str | None = None):
        super().__init__(message)
        self.option = option


class DataError(JaxcalError, ValueError):
    """Bad measurement or array input: the message names the row, column or parameter."""


class RobotFileError(JaxcalError, ValueError):
    """A robot description (TOML, URDF or constructor arguments) is malformed."""


class PrecisionError(JaxcalError, RuntimeError):
    """float64 is not available (``jax_enable_x64`` was switched off)."""


class ImplausibleFitError(JaxcalError, ValueError):
    """A fit converged but is not a calibration: its residuals or parameter changes are
    implausible for the robot, usually because of a mistake in the input (units, column
    order, quaternion order). The message names the evidence and the likely causes."""


class CalibrationWarning(UserWarning):
    """A calibration was returned that is not one to use: implausible (``strict`` off) or not
    converged. Its ``plausible``/``converged`` say so too; saving it is the caller's choice."""


def warn_unusable(converged: bool, implausible: str, what: str = "calibration") -> None:
    """Warn (:class:`CalibrationWarning`) when a returned fit did not converge or is implausible:
    a script that saves the result without looking would otherwise write it silently."""
    import warnings

    said = ([] if converged else ["did not converge (converged is False)"]) + (
        [f"is not plausible: {implausible}"] if implausible else []
    )
    if said:
        warnings.warn(f"this {what} is not one to use: it {'; it '.join(said)}", CalibrationWarning, stacklevel=3)
