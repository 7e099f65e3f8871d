"""jaxcal: calibration of the Denavit-Hartenberg parameters of serial robot arms, in JAX.

Importing jaxcal enables float64 in JAX (``jax_enable_x64``); see :mod:`jaxcal._config`.
Units inside jaxcal: millimetres and radians.
"""

from . import _config  # noqa: F401  (enables float64 first)
from . import derivatives, design, error_model, identifiability, kinematics, lie, measurements, presets, simulate
from .calibrate import BatchResult, CalibrationResult, calibrate, calibrate_batch
from .errors import DataError, JaxcalError, PrecisionError, RobotFileError
from .kinematics import fk, fk_frames, fk_pose_last, to_mdh, to_sdh
from ._native import status as native_status
from .presets import preset
from .robot import Robot
from .measurements import Measurements, UnitWarning, read_measurements, write_measurements
from .robot_io import load_robot, save_robot

__all__ = [
    "BatchResult", "CalibrationResult", "Measurements", "UnitWarning", "calibrate", "calibrate_batch",
    "identifiability", "measurements", "read_measurements", "simulate", "write_measurements",
    "DataError", "JaxcalError", "PrecisionError", "RobotFileError", "Robot",
    "derivatives", "error_model", "fk", "fk_frames", "fk_pose_last", "kinematics", "lie", "load_robot", "native_status",
    "preset", "presets", "save_robot", "to_mdh", "to_sdh",
]
__version__ = "0.1.0"
