"""Calibration: one fit (:func:`calibrate`), many data sets of one robot at once
(:func:`calibrate_batch`), and the real-data workflow with cross-validation
(:func:`calibrate_data`, behind ``jaxcal calibrate``), all on the one engine."""

from ._accuracy import position_std as position_std
from ._checks import check_angles as check_angles
from ._checks import check_units as check_units
from ._core import base_set as base_set
from ._core import generic_model as generic_model
from ._core import kin_order as kin_order
from ._core import nominal_model as nominal_model
from ._core import parallel_snapped as parallel_snapped
from ._evaluate import evaluate as evaluate
from ._options import GAUGE as GAUGE
from ._options import JOINT_GAUGE as JOINT_GAUGE
from ._options import Options as Options
from ._param_sets import Candidate as Candidate
from ._param_sets import parse_params as parse_params
from ._selection import lever as lever
from ._single import BatchResult as BatchResult
from ._single import CalibrationResult as CalibrationResult
from ._single import calibrate as calibrate
from ._single import calibrate_batch as calibrate_batch
from ._single import identify as identify
from ._single import make_layout as make_layout
from ._single import still_joint_notes as still_joint_notes
from ._workflow import DataCalibration as DataCalibration
from ._workflow import calibrate_data as calibrate_data
from ._workflow import fold_ids as fold_ids
