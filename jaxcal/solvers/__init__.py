"""Calibration solvers: the one Gauss–Newton / Levenberg–Marquardt engine (optimistix) and the
paper's joint-by-joint elimination method with its pose designs."""

from ._elimination import EliminationPlan as EliminationPlan
from ._elimination import calibrate_design_batch as calibrate_design_batch
from ._elimination import eliminate as eliminate
from ._elimination import eliminate_batch as eliminate_batch
from ._elimination import make_plan as make_plan
from ._elimination import step_conditions as step_conditions
from ._elimination_design import PairLayout as PairLayout
from ._elimination_design import check_design as check_design
from ._elimination_design import design_poses as design_poses
from ._elimination_design import infer_layout as infer_layout
from ._engine import LOSSES as LOSSES
from ._engine import METHODS as METHODS
from ._engine import OUTLIER_SIGMAS as OUTLIER_SIGMAS
from ._engine import PIN as PIN
from ._engine import Solution as Solution
from ._engine import fit as fit
from ._engine import gauss_newton as gauss_newton
from ._engine import least_squares as least_squares
from ._engine import outlier_threshold as outlier_threshold
from ._engine import robust_scale as robust_scale
from ._engine import robust_weights as robust_weights
from ._engine import tuning as tuning
