"""jaxcal: geometric calibration of serial robot arms, in JAX (float64, jit, vmap).

Importing jaxcal enables float64 in JAX (``jax_enable_x64``). Units inside jaxcal: millimetres
and radians; files are read and written in their own units.
"""

from . import _config  # noqa: F401  (enables float64 first)
from .calibration import BatchResult as BatchResult
from .calibration import CalibrationResult as CalibrationResult
from .calibration import DataCalibration as DataCalibration
from .calibration import Options as Options
from .calibration import calibrate as calibrate
from .calibration import calibrate_batch as calibrate_batch
from .calibration import calibrate_data as calibrate_data
from .calibration import evaluate as evaluate
from .compensation import Compensation as Compensation
from .compensation import compensate as compensate
from .errors import CalibrationWarning as CalibrationWarning
from .errors import DataError as DataError
from .errors import ImplausibleFitError as ImplausibleFitError
from .errors import JaxcalError as JaxcalError
from .errors import PrecisionError as PrecisionError
from .errors import RobotFileError as RobotFileError
from .export import save_dh_table as save_dh_table
from .export import save_report as save_report
from .export import save_ur_kinematics as save_ur_kinematics
from .kinematics import fk as fk
from .kinematics import fk_frames as fk_frames
from .kinematics import to_joint as to_joint
from .kinematics import to_mdh as to_mdh
from .kinematics import to_sdh as to_sdh
from .measurements import Measurements as Measurements
from .measurements import read_measurements as read_measurements
from .measurements import write_measurements as write_measurements
from .model import Layout as Layout
from .model import Model as Model
from .model import load_model as load_model
from .model import save_model as save_model
from .robot import Robot as Robot
from .robot import load_robot as load_robot
from .robot import preset as preset
from .robot import save_robot as save_robot
from .simulation import simulate as simulate

__version__ = "0.3.0"
