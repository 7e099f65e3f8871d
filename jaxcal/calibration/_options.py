"""The options of every calibration entry point, with their defaults, in one place.

:func:`jaxcal.calibrate`, :func:`jaxcal.calibrate_batch`, :func:`jaxcal.calibrate_data` and the
``jaxcal calibrate`` command take the same options with the same defaults; the command's flags
are these names with dashes (``estimate_base`` -> ``--estimate-base/--no-estimate-base``).
"""

from __future__ import annotations

import dataclasses
import math
import numbers

from ..camera import CAMERA_MODELS
from ..errors import DataError
from ..solvers import LOSSES, METHODS, OUTLIER_SIGMAS

ELIMINATION_METHODS = ("elimination", "elimination-literal")
GAUGE = (
    "DH values are the nominal table plus the estimated changes; a change the base or tool frame can absorb "
    "(theta1, d1, the last joint's offset, ...) is held at 0 and carried by that frame; joint offsets are "
    "within half a turn of the nominal ones, up to whole turns (a TOML file writes an angle beyond a whole "
    "turn within one)"
)
"""How a calibrated model's parameters are fixed where several give the same kinematics: written into
the robot files the command line saves."""
JOINT_GAUGE = (
    "joint origins are the nominal ones with the estimated corrections folded in; a correction the base, the "
    "tool or another joint's can absorb (a turn about a joint's own axis, a shift along a common normal, ...) "
    "is held at 0 and carried there; joint offsets are within half a turn of the nominal ones"
)
"""The same for a joint-frame (URDF) model."""
CAMERA_CHOICES = CAMERA_MODELS + ("auto",)
COMPLIANCE_CHOICES = ("auto", "yes", "no")


@dataclasses.dataclass(frozen=True)
class Options:
    """Calibration options (lengths mm, angles rad).

    **Model**

    - ``params`` (``"auto"``): which DH errors may move. ``"frames"`` (none: base and tool only),
      ``"offsets"`` (joint offsets theta), ``"angles"`` (theta and alpha), ``"all"``, or a comma
      list of kinds (``theta, d, a, alpha``) and names (``theta2, a4``). ``"auto"``: in
      :func:`calibrate_data` the model chosen by held-out error on new postures and beyond the
      training ranges, down to single parameters (:mod:`._selection`); a single fit
      (:func:`calibrate`) uses ``"all"``. Parameters the poses cannot identify are held at 0
      whatever the set.
    - ``ridge_mm`` (None): a prior on the parameters of an explicit ``params`` set, physically
      scaled: each parameter is expected to move the measured points by about this many mm
      (:meth:`Candidate.prior_weight`; an angle's prior is ``ridge_mm`` over its lever arm).
      :func:`calibrate_data` refuses it with ``params="auto"``, which chooses its own prior.
    - ``estimate_base`` (True), ``estimate_tool`` (True): estimate the measurement frame -> robot
      base transform and the tool (a frame for poses, a point per measured point), starting
      from a closed-form guess. The base keeps what belongs to it: a DH error that the base or
      tool frame can absorb (``theta1``, ``d1``, the last joint's offset, ...) is held at 0.
    - ``compliance`` (``"auto"``): estimate a compliance per revolute joint, a turn proportional to
      the gravity moment of a weight at the tool (:attr:`jaxcal.Robot.compliance`): ``"yes"``,
      ``"no"``, or ``"auto"`` (in :func:`calibrate_data` the model selection decides; a single
      fit, :func:`calibrate`, is rigid).
    - ``camera`` (``"none"``): a camera measurement model (:mod:`jaxcal.camera`) for pose data
      from a camera on the flange, ``none | depth | linear | quadratic``, or ``auto`` (chosen by
      cross-validation, :func:`calibrate_data` only).

    **Weights and losses**

    - ``sigma_pos_mm``, ``sigma_rot_rad`` (None): measurement noise per coordinate, which weights
      position against rotation rows. None: estimated from the residual of the frames-only fit
      (the RMS per coordinate and per axis), at least 1e-3 mm and 1e-6 rad (noise-free data
      would otherwise weight rounding errors). ``sigma_rot_rad`` with position data is refused: no
      rotation was measured to weigh.
    - ``loss`` (``"l2"``), ``loss_scale`` (None): ``huber`` or ``cauchy`` make the fit robust to
      outlier poses (iteratively reweighted), ``loss_scale`` the noise scale per row in units of
      sigma (None: a robust estimate; refused with ``l2``, which has no scale).

    **Outliers** (:mod:`jaxcal.calibration._outliers`)

    - ``outlier_sigmas`` (5): a pose whose residual is as improbable under the estimated noise as
      a one-sided 5-sigma normal deviation (2.9e-7 per pose) is an outlier: named in the report
      and left out of the fit (and of every cross-validation fit and held-out figure).
    - ``keep_outliers`` (False): find and name them, but fit every pose.
    - ``max_outlier_fraction`` (0.2): more outliers than this share of the poses make the fit
      implausible (refused by the command line), with the worst rows named.

    **Solver**

    - ``method`` (``"gn"``): ``gn`` (Gauss–Newton), ``lm`` (Levenberg–Marquardt), both optimistix,
      or ``linear`` (one Gauss–Newton step from the start); :func:`calibrate_batch` also takes
      the paper's ``elimination`` and ``elimination-literal`` (an elimination pose design, full
      poses, known frames).
    - ``max_steps`` (50), ``rtol`` (1e-8), ``atol`` (1e-8): optimistix's limits and tolerances, on
      parameters scaled to comparable size and on residuals in units of sigma (for the elimination
      methods: at most ``max_steps`` sweeps, until no parameter moves more than ``atol`` mm/rad).

    **Cross-validation** (:func:`calibrate_data`)

    - ``folds`` (5), ``seed`` (0): K-fold cross-validation with a seeded fold assignment.
    - ``nested_max_poses`` (1000): the held-out figures come from nested cross-validation (the
      parameter set chosen again inside each training set) up to this many poses; above it, from
      plain K-fold, whose optimism in choosing among a few sets is negligible with that much
      data, at a fifth of the cost.

    **Plausibility** (:mod:`jaxcal.calibration._plausibility`): a fit beyond these is not a
    calibration; it is marked (``plausible`` False, with the evidence and the likely input
    mistake), ``strict`` makes it an error, and the command line writes nothing.

    - ``max_residual_mm`` (None: 1 % of the robot's reach), ``max_rotation_deg`` (2): the
      calibrated position and rotation RMS.
    - ``max_length_change_mm`` (None: 5 % of the reach), ``max_angle_change_deg`` (20): the
      largest change of a DH length and angle, and of any standard error.
    - ``max_camera_change`` (0.1): the largest camera unknown (dimensionless).
    - ``strict`` (False): raise :class:`jaxcal.ImplausibleFitError` instead of marking.

    **Resources**

    - ``memory_mb`` (1024): fits of many data sets (or training sets) run in chunks sized to
      this budget, so memory grows with the data, not with their number.
    """

    method: str = "gn"
    params: str = "auto"
    ridge_mm: float | None = None
    estimate_base: bool = True
    estimate_tool: bool = True
    camera: str = "none"
    compliance: str = "auto"
    sigma_pos_mm: float | None = None
    sigma_rot_rad: float | None = None
    loss: str = "l2"
    loss_scale: float | None = None
    outlier_sigmas: float = OUTLIER_SIGMAS
    keep_outliers: bool = False
    max_outlier_fraction: float = 0.2
    max_steps: int = 50
    rtol: float = 1e-8
    atol: float = 1e-8
    folds: int = 5
    seed: int = 0
    nested_max_poses: int = 1000
    max_residual_mm: float | None = None
    max_rotation_deg: float = 2.0
    max_length_change_mm: float | None = None
    max_angle_change_deg: float = 20.0
    max_camera_change: float = 0.1
    strict: bool = False
    memory_mb: float = 1024.0

    def checked(self, *, elimination: bool = False, camera_auto: bool = False) -> "Options":
        """Raise :class:`jaxcal.DataError` (naming the option) for a bad value; return ``self``."""
        methods = METHODS + (ELIMINATION_METHODS if elimination else ())
        if self.method not in methods:
            raise DataError(f"method must be one of {', '.join(methods)}, got {self.method!r}", option="method")
        cams = CAMERA_CHOICES if camera_auto else CAMERA_MODELS
        if self.camera not in cams:
            raise DataError(f"camera must be one of {', '.join(cams)}, got {self.camera!r}", option="camera")
        if self.compliance not in COMPLIANCE_CHOICES:
            raise DataError(
                f"compliance must be one of {', '.join(COMPLIANCE_CHOICES)}, got {self.compliance!r}",
                option="compliance",
            )
        if self.loss not in LOSSES:
            raise DataError(f"loss must be one of {', '.join(LOSSES)}, got {self.loss!r}", option="loss")
        if self.loss == "l2" and self.loss_scale is not None:  # it would only set the outliers' noise scale
            raise DataError(
                f"loss_scale {self.loss_scale!r} is the scale of a robust loss (huber or cauchy); loss 'l2' has none",
                option="loss_scale",
            )
        if self.loss != "l2" and self.method not in ("gn", "lm"):
            raise DataError(
                f"loss {self.loss!r} needs method 'gn' or 'lm' (iteratively reweighted), got {self.method!r}",
                option="loss",
            )
        for name in (
            "sigma_pos_mm",
            "sigma_rot_rad",
            "loss_scale",
            "ridge_mm",
            "max_residual_mm",
            "max_length_change_mm",
        ):
            v = getattr(self, name)
            if v is None:
                continue
            if not _number(v) or not math.isfinite(v) or v <= 0:
                raise DataError(f"{name} must be a finite positive number (or None), got {v!r}", option=name)
        for name, lo in (("max_steps", 1), ("folds", 2), ("seed", 0), ("nested_max_poses", 0)):
            v = getattr(self, name)
            if not isinstance(v, numbers.Integral) or isinstance(v, bool) or v < lo:
                raise DataError(f"{name} must be an integer >= {lo}, got {v!r}", option=name)
        if not isinstance(self.keep_outliers, bool):
            raise DataError(f"keep_outliers must be True or False, got {self.keep_outliers!r}", option="keep_outliers")
        v = self.max_outlier_fraction
        if not _number(v) or not 0 < v <= 1:
            raise DataError(f"max_outlier_fraction must be in (0, 1], got {v!r}", option="max_outlier_fraction")
        for name in (
            "rtol",
            "atol",
            "memory_mb",
            "max_rotation_deg",
            "max_angle_change_deg",
            "max_camera_change",
            "outlier_sigmas",
        ):
            v = getattr(self, name)
            if not _number(v) or not math.isfinite(v) or v <= 0:
                raise DataError(f"{name} must be a finite positive number, got {v!r}", option=name)
        return self


def _number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def make_options(options: Options | None, kw: dict, **check) -> Options:
    """``options`` with the keyword overrides ``kw`` applied, checked; unknown keywords are an
    error naming the known ones."""
    base = Options() if options is None else options
    known = {f.name for f in dataclasses.fields(Options)}
    unknown = sorted(set(kw) - known)
    if unknown:
        raise DataError(f"unknown option(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}", option=unknown[0])
    return dataclasses.replace(base, **kw).checked(**check)
