"""Optimal pose design: which joint configurations to measure so that a calibration is most
accurate (D-, A-optimal, or the expected validation position error from the Cramér–Rao bound),
by gradient through the identification Jacobian (:func:`optimal_poses`) or by exchange from a
pool of candidates (:func:`select_poses`); random poses under the same conditions
(:class:`PoseSampler`, :func:`random_poses`); pose files (:func:`read_poses`, :func:`write_poses`).
See docs/design.md."""

from ._bound import design_bound as design_bound
from ._constraints import PoseSampler as PoseSampler
from ._constraints import Workspace as Workspace
from ._constraints import constraints as constraints
from ._constraints import feasible as feasible
from ._constraints import in_region as in_region
from ._constraints import min_distance as min_distance
from ._constraints import random_poses as random_poses
from ._constraints import workspace as workspace
from ._files import read_poses as read_poses
from ._files import write_poses as write_poses
from ._optimize import objective_and_grad as objective_and_grad
from ._optimize import optimal_poses as optimal_poses
from ._problem import CRITERIA as CRITERIA
from ._problem import DEFAULT_POINT_MM as DEFAULT_POINT_MM
from ._problem import LIMIT_MARGIN as LIMIT_MARGIN
from ._problem import DesignProblem as DesignProblem
from ._problem import design_problem as design_problem
from ._problem import evaluate as evaluate
from ._problem import information as information
from ._problem import loss as loss
from ._problem import with_criterion as with_criterion
from ._report import report_options as report_options
from ._report import report_points as report_points
from ._result import PoseDesign as PoseDesign
from ._result import matching_count as matching_count
from ._select import select_poses as select_poses
