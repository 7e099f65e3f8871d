"""One fit of one data set (:func:`calibrate`) or of many data sets of one robot at once
(:func:`calibrate_batch`), on the one engine (:mod:`jaxcal.solvers`).

The pipeline: the closed-form guess of the frames; the identifiable (base) set over the poses,
frames offered first; a frames-only fit (DH held), whose residual gives the noise weights when
none are given; the fit of the chosen parameter set; the outliers (:mod:`._outliers`), and when
there are some, the whole pipeline again without them; residual statistics, standard errors.
Every stage runs through one compiled solve (:mod:`._core`).
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
from jaxtyping import Bool

from .._config import as_f64
from ..camera import n_params as camera_size
from ..errors import DataError, ImplausibleFitError, warn_unusable
from ..identifiability import Identifiability
from ..kinematics import check_q
from ..model import Layout, Model, measured_robot, observed, predict
from ..robot import Robot
from ..sharding import describe, select_devices
from ..solvers import PIN, calibrate_design_batch
from . import _core as core
from . import _outliers as outliers
from . import _plausibility as plausibility
from . import _selection as selection
from ._checks import as_target, check_rigid_points, check_units, limit_notes, lost_points
from ._core import nominal_model
from ._options import ELIMINATION_METHODS, Options, make_options
from ._param_sets import Candidate, parse_params


@dataclasses.dataclass(frozen=True, eq=False)
class CalibrationResult:
    """What :func:`calibrate` returns (lengths mm, angles rad unless named)."""

    model: Model
    """The calibrated model: robot, measured points on the tool, camera unknowns."""
    nominal: Robot
    layout: Layout
    x: np.ndarray
    """``(m,)`` parameters relative to the nominal robot, named by :attr:`names`: ``apply(
    Model(nominal), layout, x)`` is :attr:`model`, but for a model with joint compliances, whose
    offsets hold at its reference moments (:attr:`jaxcal.Robot.moment_ref`, set to the mean over
    the poses fitted): the nominal robot with ``moment_ref=model.robot.moment_ref`` then. An
    offset held but moved by its compliance so is not 0 (:func:`._core.centred`)."""
    std_errors: np.ndarray
    """``(m,)`` 1-sigma standard errors (0 for parameters held at 0; an offset moved by its
    compliance carries the compliance's error times the moment's shift)."""
    identifiability: Identifiability
    free: tuple[int, ...]
    """Indices of the estimated parameters."""
    converged: bool
    num_steps: int
    before: dict
    """Residual statistics of the frames-only fit (nominal DH): ``pos_rms_mm``, ``pos_max_mm``,
    ``pos_median_mm``, ``rot_rms_deg`` for poses."""
    after: dict
    """Residual statistics of the calibrated model."""
    sigma_pos_mm: float
    sigma_rot_rad: float | None
    """The rows' weights (1-sigma per coordinate): the caller's; for points, the frames-only
    fit's residual, which holds the robot's own errors too; for poses, the calibrated fit's robust
    residual where the fit reweighs (not the linear method), else the frames-only one. The noise
    left after the fit is ``robust_scale`` times them."""
    method: str
    loss: str
    outliers: tuple[int, ...]
    """Poses (indices) found to be outliers (:mod:`._outliers`): left out of the fit and of
    :attr:`before` and :attr:`after`, unless ``keep_outliers``."""
    degraded: bool
    """Outliers spoil this fit: kept in a plain (L2) fit (``keep_outliers``), or more than
    ``max_outlier_fraction`` of the poses."""
    robust_scale: float
    """The noise scale per row (units of sigma) over the poses fitted."""
    sigmas: np.ndarray
    """``(K,)`` each pose's residual norm in units of the noise per row (``robust_scale``)."""
    outlier_threshold: np.ndarray
    """``(K,)`` each pose's threshold on :attr:`sigmas`."""
    pos_errors_mm: np.ndarray
    """``(K, M)`` position error of every measured point after calibration."""
    options: Options
    plausible: bool = True
    """False: the fit is not a calibration (see :attr:`implausible`)."""
    implausible: str = ""
    """Why the fit is not a calibration, its evidence and the likely input mistake."""
    notes: tuple[str, ...] = ()
    """Warnings that do not make the fit implausible (a joint that never moves, ...)."""

    @property
    def robot(self) -> Robot:
        """The calibrated robot (base and tool included)."""
        return measured_robot(self.model)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.layout.names())

    @property
    def num_points(self) -> int:
        return self.layout.n_points

    def not_identified(self) -> dict[str, str]:
        """``{parameter: why}`` for every parameter held at 0 by the identifiability analysis; a
        joint that never moves in the data is named as a likely cause."""
        still = [n.split(" never moves")[0] for n in self.notes if " never moves in the data" in n]
        hint = f"; {' and '.join(still)} never move{'s' if len(still) == 1 else ''} in the data" if still else ""
        return {k: v + hint for k, v in self.identifiability.reasons().items()}

    def delta(self, name: str) -> float:
        return float(self.x[self.names.index(name)])

    def table(self) -> str:
        held = set(range(len(self.x))) - set(self.free)
        units = self.layout.units()
        lines = [f"{'parameter':>14s} {'delta':>14s} {'std err':>11s} unit"]
        for i, (n, v, s) in enumerate(zip(self.names, self.x, self.std_errors)):
            # a held offset its compliance moved to the reference moments (core.centred) is not 0
            said = ("  (held at 0)" if v == 0 else "  (held; moved by its compliance)") if i in held else ""
            lines.append(f"{n:>14s} {v:14.8g} {s:11.3g} {units[i]:4s}" + said)
        return "\n".join(lines)


@dataclasses.dataclass(frozen=True, eq=False)
class BatchResult:
    """What :func:`calibrate_batch` returns (leading axis: data sets)."""

    x: np.ndarray
    """``(R, m)`` parameters relative to the nominal robot."""
    converged: np.ndarray
    num_steps: np.ndarray
    identifiability: Identifiability
    layout: Layout
    method: str
    loss: str = "l2"
    outlier_mask: np.ndarray | None = None
    """``(R, K)``: outliers (see :attr:`CalibrationResult.outliers`), left out of each data
    set's fit unless ``keep_outliers``."""
    degraded: np.ndarray | None = None
    nonfinite: np.ndarray | None = None
    """``(R,)``: the solver gave non-finite values; ``x`` is 0 there, not converged."""
    devices: tuple[str, ...] = ()
    """The devices the data sets were shared over (:func:`jaxcal.sharding.describe`)."""
    problems: tuple[str, ...] = ()
    """Per data set, why its poses cannot identify what a generic pose set does (a joint that
    never moves, too few distinct poses, a point never measured; not converged then), or ""."""
    rechosen: np.ndarray | None = None
    """``(R,)``: data sets whose fit ran where the batch's parameter set is not separable (an arm
    far from its file), fitted again with the set identifiable at their fit, as
    :func:`calibrate` does; ``x`` keeps the batch's layout, with the parameters that set holds
    at 0."""
    estimated: Bool[np.ndarray, "R m"] | None = None
    """The parameters each data set estimated (:attr:`CalibrationResult.free` as a mask); the
    others are held at 0 in ``x``. A member in :attr:`rechosen` has its own; one named in
    :attr:`problems` or :attr:`nonfinite` none. None for the elimination methods."""
    implausible: tuple[str, ...] = ()
    """Per data set, why its fit is not a calibration (empty: plausible), in :func:`calibrate`'s
    words (:func:`._plausibility.findings`): its residual and each parameter's change (angles
    within half a turn) against the limits of :class:`jaxcal.Options`, the limits from every data
    set's poses. Not judged here, as calibrate judges them: the standard errors, too many
    outliers, too few distinct poses (:attr:`problems` names those), and the search for an input
    mistake. Empty for the elimination methods."""

    @property
    def plausible(self) -> np.ndarray:
        """``(R,)``: :attr:`implausible` is empty."""
        return np.array([not w for w in self.implausible]) if self.implausible else np.ones(len(self.x), bool)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.layout.names())

    def outliers(self, i: int) -> tuple[int, ...]:
        return tuple(int(k) for k in np.flatnonzero(self.outlier_mask[i]))


def kinematic_set(opts: Options, robot: Robot) -> Candidate:
    """The one parameter set of a single fit: ``params`` (``auto`` = ``all``) with ``ridge_mm``, and
    the camera model's unknowns."""
    spec = "all" if opts.params == "auto" else opts.params
    return dataclasses.replace(
        parse_params(spec, robot, opts.ridge_mm)[0], camera=opts.camera, compliance=opts.compliance == "yes"
    )


def make_layout(
    robot: Robot,
    opts: Options,
    n_points: int,
    camera: str | None = None,
    compliance: bool | None = None,
    point_numbers: tuple[int, ...] = (),
) -> Layout:
    """The parameters a fit with these options carries; ``camera`` and ``compliance`` override the
    options' (a workflow's layout holds every candidate's); ``point_numbers`` name the points'
    parameters by the data file's numbers."""
    camera = opts.camera if camera is None else camera
    compliance = opts.compliance == "yes" if compliance is None else compliance
    if n_points and camera != "none":
        raise DataError(
            f"the camera model {camera!r} needs full poses (the camera's axes); the data are position-only",
            option="camera",
        )
    if n_points and opts.sigma_rot_rad is not None:  # else accepted and weighing nothing
        raise DataError(
            f"sigma_rot_rad {opts.sigma_rot_rad:g}: the noise of measured rotations; the data are positions "
            "(no rotation measured), weighted by sigma_pos_mm alone",
            option="sigma_rot_rad",
        )
    if n_points > 1 and not opts.estimate_tool:
        raise DataError(
            f"{n_points} points per pose: their positions on the tool are unknown and must be "
            f"estimated (estimate_tool)",
            option="estimate_tool",
        )
    return Layout.of(
        robot,
        base=opts.estimate_base,
        tool=opts.estimate_tool,
        n_points=n_points,
        camera=camera,
        compliance=compliance,
        point_numbers=point_numbers,
    )


def check_enough_poses(n_poses: int, layout: Layout, needed: int, n_rows: int | None = None) -> None:
    """Refuse ``n_poses`` distinct poses (of ``n_rows`` data rows, when some repeat a joint vector)
    that give fewer equations than the ``needed`` parameters."""
    rows = layout.rows
    if n_poses * rows < needed:
        d = "distinct " if n_rows is not None and n_rows > n_poses else ""
        repeats = (
            f" (the other {n_rows - n_poses} of {n_rows} rows repeat their joint values, and a repeated row "
            f"adds no equation)"
            if d
            else ""
        )
        raise DataError(
            f"too few poses: {n_poses} {d}poses{repeats} x {rows} rows = {n_poses * rows} equations for "
            f"{needed} parameters; need at least {-(-needed // rows)} {d}poses",
            option="q" if d else "measured",
        )


def few_distinct(q, grid, rows: int, needed: int) -> str:
    """A finding when the rows of ``q (K, n)`` repeat joint values so that the distinct poses give
    fewer equations than the ``needed`` parameters a varied pose set identifies ("" otherwise;
    ``grid``: :func:`._core.same_pose`)."""
    K, d = len(q), int(core.distinct_poses(q, grid))
    if d == K or d * rows >= needed:
        return ""
    return (
        f"only {d} of the {K} data rows have distinct joint values ({d} x {rows} rows = {d * rows} equations "
        f"for the {needed} parameters a varied pose set identifies): the fit reproduces these poses and "
        f"not others; measure more distinct postures"
    )


def prior_of(layout: Layout, ident: Identifiability, cand: Candidate | None, *, frames_only: bool = False, lever=None):
    """Prior weight of every parameter of the layout: :data:`PIN` (held at 0) for what the poses
    cannot identify and what the candidate (``None``: frames only) does not estimate; a
    candidate's DH errors and compliances their physically scaled prior weight
    (:meth:`Candidate.prior_weight`, ``lever (m,)`` from :func:`._selection.lever`; 0 without a
    prior); frames and the candidate camera model's unknowns 0."""
    base = set(ident.base)
    out = np.zeros(layout.size)
    cams, comps = layout.cameras, set(layout.compliances)
    for i in range(layout.size):
        if i not in base:
            out[i] = PIN
        elif i < layout.n_kin or i in comps:
            if frames_only or cand is None or not (i in cand.dh if i < layout.n_kin else cand.compliance):
                out[i] = PIN
            else:
                out[i] = 0.0 if cand.ridge_mm is None else cand.prior_weight(lever[i])
        elif i in cams:
            k = i - cams[0]
            out[i] = PIN if frames_only or cand is None or k >= camera_size(cand.camera) else 0.0
    return out


REWEIGHTS = 3
"""Poses: how many times the position and rotation weights are taken again from the calibrated
fit's residual. The frames-only residual is the arm's geometric errors, not the noise, and its
ratio of millimetres to radians is not the noise's: weighted by it, the rotation rows count too
little or too much, the estimates are noisier than they need be, and the standard errors, which
pool one variance over both kinds of rows, miss the spread of the estimates. Not for the one-shot
``linear`` method."""
REWEIGHT_TOLERANCE = 1.1
"""Weights taken again until neither sigma changes by more than this factor."""


def _lead(mask, ndim: int):
    """``mask (R,)`` shaped to broadcast against an ``ndim`` array with the members first."""
    return np.reshape(mask, (-1,) + (1,) * (ndim - 1))


def _given(sig, opts: Options):
    """``(B, 2)`` sigmas with the caller's ``sigma_pos_mm`` / ``sigma_rot_rad`` in place."""
    sig = np.array(sig, float)
    if opts.sigma_pos_mm is not None:
        sig[:, 0] = opts.sigma_pos_mm
    if opts.sigma_rot_rad is not None:
        sig[:, 1] = opts.sigma_rot_rad
    return sig


def member_priors(layout: Layout, ident: Identifiability, cand: Candidate, lever) -> np.ndarray:
    """:func:`prior_of` of every member, ``lever (R, m)`` each one's: ``(R, m)``."""
    unit = prior_of(layout, ident, cand, lever=np.ones(layout.size))
    if cand.ridge_mm is None:
        return np.repeat(unit[None], len(lever), 0)
    scaled = (unit > 0) & (unit < PIN)  # the parameters the candidate's prior holds
    return np.where(scaled, np.asarray(lever) / cand.ridge_mm, unit)


def estimated(prior) -> tuple[int, ...]:
    return tuple(int(i) for i in np.flatnonzero(np.asarray(prior) < PIN))


def judge(
    robot: Robot,
    q,
    target,
    n_points: int,
    layout: Layout,
    opts: Options,
    stats: dict,
    x,
    free,
    extra: str = "",
    *,
    se=None,
    cause: str = "",
) -> str:
    """Empty when the fit is plausible as a calibration; else why not and the likely input
    mistake (:mod:`._plausibility`). ``extra``: a further finding (too many outliers,
    :func:`._outliers.too_many`); ``cause``: its cause, found in the data themselves (marker
    labels swapped, :func:`._outliers.swaps_note`), which the input mistakes then need not be
    tried for. Raises :class:`jaxcal.ImplausibleFitError` with ``strict``."""
    limits = plausibility.Thresholds.of(robot, opts, q)
    found = plausibility.findings(stats, x, layout, limits, free=free, se=se) + ([extra] if extra else [])
    if not found:
        return ""
    if cause:
        message = plausibility.explain(found, None, [], limits, cause=cause)
    else:
        before, ranked = plausibility.diagnose(robot, q, target, n_points, layout, limits, memory_mb=opts.memory_mb)
        message = plausibility.explain(found, before, ranked, limits)
    if opts.strict:
        raise ImplausibleFitError(message)
    return message


def still_joint_notes(robot: Robot, q) -> tuple[str, ...]:
    """A note per joint that never moves in the data, or only by an encoder's jitter
    (:data:`._core.STILL_GRIDS`): what depends on it is not identified, and the model is only
    checked at that joint value."""
    q = np.asarray(q)
    exact, span = _still_joints(robot, q), np.ptp(q, axis=0)
    v = q / robot.joint_scale()  # the robot file's units, as the other joint notes give them
    unit = [robot.units[1] if t == "R" else robot.units[0] for t in robot.joint_types]
    return tuple(
        f"joint {j + 1} ({robot.joint_names[j]}) never moves in the data "
        + (
            f"(always {v[0, j]:.6g} {unit[j]})"
            if exact[j]
            else f"beyond {np.ptp(v[:, j]):.2g} {unit[j]} ({v[:, j].min():.6g} to {v[:, j].max():.6g}: taken as still)"
        )
        + ": its parameters are not identified apart from its neighbours', and the model is only checked there"
        for j in np.flatnonzero(span <= core.still_span(robot))
    )


NARROW_SHARE = 0.05
"""A joint that moves over less than this share of its limits in the data (of a turn, for a
revolute joint given none), more than a still joint's jitter, is named: the model is fitted, and
checked by the range-end folds, only over that span."""


def narrow_joint_notes(robot: Robot, q) -> tuple[str, ...]:
    """A note per joint that moves over less than :data:`NARROW_SHARE` of its range: where the
    arm goes beyond that span, the model extrapolates it, and the held-out figures do not say how
    well (``evaluate`` warns of such postures)."""
    q = np.asarray(q)
    span, lim, given = np.ptp(q, axis=0), np.asarray(robot.q_limits), robot.limits_given()
    revolute = np.array([t == "R" for t in robot.joint_types])
    width = np.where(given, lim[:, 1] - lim[:, 0], 2 * np.pi)  # a revolute joint without limits: a turn
    narrow = (given | revolute) & (span < NARROW_SHARE * width) & (span > core.still_span(robot))
    scale = robot.joint_scale()  # the robot file's units, as the other joint notes give them
    unit = [robot.units[1] if t == "R" else robot.units[0] for t in robot.joint_types]
    return tuple(
        f"joint {j + 1} ({robot.joint_names[j]}) moves over only {span[j] / scale[j]:.3g} {unit[j]} in the data "
        f"({q[:, j].min() / scale[j]:.6g} to {q[:, j].max() / scale[j]:.6g}, {100 * span[j] / width[j]:.1f} % of "
        f"{'its limits' if given[j] else 'a turn'}): the model is fitted and its held-out figures checked only "
        "over that span; beyond it the model extrapolates by an error they do not show"
        for j in np.flatnonzero(narrow)
    )


def identify(robot: Robot, q, options: Options | None = None, /, *, n_points: int = 0, **kw) -> Identifiability:
    """Identifiability of the parameters a calibration with these options would carry, over the
    poses ``q (K, n)`` at the nominal robot (frames offered first, as in :func:`calibrate`);
    ``n_points`` points per pose (at generic places on an estimated tool,
    :func:`._core.generic_model`: a marker on the last joint's axis identifies less, which
    :func:`calibrate` finds from its data), 0 for poses."""
    opts = make_options(options, kw, elimination=True)
    layout = make_layout(robot, opts, n_points)
    q = np.asarray(check_q(robot, as_f64(q, "q")))
    if q.ndim != 2:
        raise DataError(f"q must have shape (K, {robot.n_joints}), got {q.shape}", option="q")
    return core.identified(core.generic_model(robot, layout), layout, q, robot)


def calibrate(
    robot: Robot,
    q,
    measured,
    options: Options | None = None,
    /,
    *,
    position_only: bool | None = None,
    progress=None,
    **kw,
) -> CalibrationResult:
    """Calibrate ``robot`` from joint values ``q (K, n)`` and measurements: positions ``(K, 3)``,
    points ``(K, M, 3)`` (several points on the tool per pose) or poses ``(K, 4, 4)``
    (``position_only=True`` uses only their translations); mm and rad.

    **Options**: :class:`jaxcal.Options`, or its fields as keywords (``method="lm"``); the same
    defaults as :func:`calibrate_data` and ``jaxcal calibrate``. One difference: on full poses
    without the noise given, the position and rotation weights are taken again from this fit's
    residual (:data:`REWEIGHTS`), where :func:`calibrate_data` keeps the frames-only residual's,
    with which its model selection scored the candidates.

    **Returns** a :class:`CalibrationResult`; ``converged`` is False (never silently) when the
    solver did not meet its tolerances; ``not_identified()`` says which parameters were held at
    0 and why; ``outliers`` the poses left out (:mod:`._outliers`; ``keep_outliers`` fits them).
    A point lost at a pose is NaN (all three coordinates) and weighs nothing; a pose with no point
    seen is refused (leave it out), where :func:`calibrate_batch` leaves it out of its data set.

    **Raises** :class:`jaxcal.DataError` for bad input (shapes, non-finite values, poses that are
    not rigid, lengths apparently not in mm, too few poses, bad options).
    """
    opts = make_options(options, kw)
    q, target, n_points = as_target(robot, q, measured, batched=False, position_only=position_only)
    if n_points:
        check_rigid_points(target, q, np.asarray(robot.revolute_mask, bool))
    layout = make_layout(robot, opts, n_points)
    K = q.shape[0]
    cand = kinematic_set(opts, robot)
    wanted = list(layout.frames + layout.cameras) + [i for i in range(layout.n_kin) if i in cand.dh]
    wanted += list(layout.compliances) if cand.compliance else []
    check_enough_poses(K, layout, len(wanted) if K < 2 else 0)
    masks = np.ones((1, K))
    cfg = core.Config(layout, opts.method, opts.max_steps, opts.rtol, opts.atol, opts.loss, shared_data=True)
    nominal = core.broadcast_model(nominal_model(robot, layout), 1)
    # the solve and the analysis compile in the background while the start is found (the solve,
    # the longer compile, first)
    core.prepare_members(cfg, nominal, q, target, masks, memory_mb=opts.memory_mb)
    core.prepare_analysis(core.member(nominal, 0), layout, q)

    def start(masks):
        if not layout.frames:
            return nominal
        return core.start_models(robot.stripped(), layout, q, target, masks, shared=True)

    ref = start(masks)
    needed = core.generic_rank(core.generic_model(robot, layout), layout, K, wanted)
    check_enough_poses(K, layout, needed)
    J0, pos0 = core.analyse(core.member(ref, 0), layout, q)
    nominal_pos = core.nominal_positions(robot, q)
    check_units(robot, q, target, n_points, batched=False, model_positions=pos0, robust=True, also=nominal_pos)
    ident = core.identified(core.member(ref, 0), layout, q, robot, J=J0)
    run = dict(J0=J0, memory_mb=opts.memory_mb, progress=progress, fallback=True)
    prior = prior_of(layout, ident, cand, lever=selection.lever(J0, n_points))
    # not the one-shot linear solve: a second solve from the first is another method's step
    reweigh = n_points == 0 and (opts.sigma_pos_mm is None or opts.sigma_rot_rad is None) and opts.method != "linear"

    def stages(ref, masks, x0=None):  # frames only (its residual gives the noise weights), then the set
        unit = core.weights_of(layout, np.array([core.UNIT_WEIGHTS]))
        frames_only = prior_of(layout, ident, None, frames_only=True)[None]
        a = core.run_members(cfg, ref, q, target, masks, unit, frames_only, **run, label="frames only")
        sig = _given(core.sigmas_from(a["pos_err"], a["rot_err"], masks, n_points), opts)[0]
        w = core.weights_of(layout, sig[None])
        b = core.run_members(
            cfg, a["model"], q, target, masks, w, prior[None], opts.loss_scale, x0=x0, **run, label="calibrating"
        )
        used = sig
        for _ in range(REWEIGHTS) if reweigh else ():
            new = _given(core.robust_sigmas(b["pos_err"], b["rot_err"], masks, n_points), opts)[0]
            if np.all(np.abs(np.log(new / used)) < np.log(REWEIGHT_TOLERANCE)):
                break
            used, w = new, core.weights_of(layout, new[None])
            b = core.run_members(
                cfg, a["model"], q, target, masks, w, prior[None], opts.loss_scale, x0=b["x"], **run, label="reweighted"
            )
        return a, sig, w, b, used

    a, sig, weights, b, used = stages(ref, masks)
    again = core.reidentified(ident, core.member(b["model"], 0), layout, q, robot, selection.MAX_CONDITION)
    # the fit ran where the nominal's base set is singular: the fit's set, from the fit (and every
    # refit without outliers from the last: that set may be singular at the nominal)
    if again is not None:
        ident, reidentified = again
        prior = prior_of(layout, ident, cand, lever=selection.lever(J0, n_points))
        a, sig, weights, b, used = stages(ref, masks, b["x"])

    def refit(w, x0):  # from the current stage's frames-only model and weights
        return core.run_members(
            cfg, a["model"], q, target, w, weights, prior[None], opts.loss_scale, x0=x0, **run, label="outliers"
        )

    det = outliers.found(b, refit, masks, target, opts)
    if det.flags.any() and not opts.keep_outliers:  # the whole fit again without them: start, frames, set
        first, kept = sig, masks * ~det.flags
        a, sig, weights, b, used = stages(start(kept), kept, b["x"] if again is not None else None)
        if sig[0] < outliers.REDETECT_SIGMA * first[0]:  # gross outliers set the weights: once more
            gross = outliers.gross(det)
            staged = None
            if gross.any() and (gross != det.flags).any():  # the gross ones alone may explain it
                alone = masks * ~gross
                staged = stages(start(alone), alone, b["x"] if again is not None else None)
                staged = staged if staged[1][0] < outliers.REDETECT_SIGMA * first[0] else None
            if staged is not None:  # the outliers of the data without the gross ones, and those
                a, sig, weights, b, used = staged
                det = outliers.found(refit(alone, b["x"]), refit, alone, target, opts)
                det = dataclasses.replace(det, flags=det.flags | gross)
            else:
                det = outliers.found(refit(masks, b["x"]), refit, masks, target, opts)
            kept = masks * ~det.flags
            a, sig, weights, b, used = stages(start(kept), kept, b["x"] if again is not None else None)
        found = dict(poses=n_points == 0, sigmas=opts.outlier_sigmas, loss_scale=opts.loss_scale)
        det = outliers.assess(b, masks, outliers.position_rows(target), excluded=det.flags, **found)
    if not np.all(np.isfinite(b["x"][0])):
        raise DataError(
            "the solver produced non-finite parameters; the data are probably inconsistent with the "
            "robot (check units and joint order)"
        )
    flags = det.flags[0]
    fitted = ~flags if not opts.keep_outliers else np.ones(K, bool)
    model = core.described(core.wrapped(core.member(b["model"], 0), robot), robot)
    st = core.fit_statistics(
        core.analyse(core.member(b["model"], 0), layout, q)[0],
        weights[0],
        fitted.astype(float),
        b["norms"][0],
        loss=opts.loss,
        loss_scale=opts.loss_scale,
        rows=layout.rows,
        seen=observed(target),
    )
    cov, _ = core.covariance(st["normal"], st["rss"], st["n_rows"], prior)
    x = core.relative_x(robot, layout, model)
    model, x, cov, _ = core.centred(model, layout, q, fitted, x, cov, list(estimated(prior)))
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    after = core.residual_stats(b["pos_err"][0], b["rot_err"][0], fitted, n_points=n_points)
    pos_mm = outliers.pose_position_mm(b["pos_err"][0])
    rot_deg = np.degrees(np.asarray(b["rot_err"][0])) if n_points == 0 else None
    many = outliers.too_many(
        flags, det.sigmas[0], pos_mm, np.arange(K), opts.max_outlier_fraction, rotation_deg=rot_deg
    )
    few = few_distinct(q, core.same_pose(robot), layout.rows, needed)
    swap = ""
    if many and n_points > 1:
        noise = float(det.scale[0, 0] * used[0])  # the detection scale is in the weights' units
        swap = outliers.swaps_note(predict(model, q), target, flags, noise, np.arange(K))
    why = judge(
        robot,
        q,
        target,
        n_points,
        layout,
        opts,
        after,
        x,
        estimated(prior),
        "; ".join(filter(None, (many, few))),
        se=se,
        cause=swap,
    )
    res = CalibrationResult(
        model=model,
        nominal=robot,
        layout=layout,
        x=x,
        std_errors=se,
        identifiability=ident,
        free=estimated(prior),
        converged=bool(b["converged"][0]),
        num_steps=int(b["steps"][0]),
        before=core.residual_stats(a["pos_err"][0], a["rot_err"][0], fitted, n_points=n_points),
        after=after,
        sigma_pos_mm=float(used[0]),
        sigma_rot_rad=None if n_points else float(used[1]),
        method=opts.method,
        loss=opts.loss,
        outliers=tuple(int(i) for i in np.flatnonzero(flags)),
        degraded=bool(flags.any() and opts.keep_outliers and opts.loss == "l2") or bool(many),
        robust_scale=st["scale"],
        sigmas=det.sigmas[0],
        outlier_threshold=det.threshold[0],
        pos_errors_mm=b["pos_err"][0],
        options=opts,
        plausible=not why,
        implausible=why,
        notes=still_joint_notes(robot, q)
        + narrow_joint_notes(robot, q)
        + limit_notes(robot, q[fitted], poses=np.flatnonzero(fitted))  # the poses fitted, indexed as outliers
        + ((reidentified,) if again is not None else ()),
    )
    warn_unusable(res.converged, res.implausible)
    return res


def calibrate_batch(
    robot: Robot,
    q,
    measured,
    options: Options | None = None,
    /,
    *,
    position_only: bool | None = None,
    ident: Identifiability | None = None,
    progress=None,
    devices: str | int | None = "all",
    **kw,
) -> BatchResult:
    """:func:`calibrate` for ``R`` data sets of the same nominal robot: ``q (R, K, n)``,
    measurements with the same leading axis. One compiled, vmapped solve run in chunks within
    ``memory_mb`` (no Python loop over data sets inside a chunk), each chunk's data sets shared
    over ``devices`` (``"all"``, a count, or ``None`` for the default device alone;
    :func:`jaxcal.sharding.select_devices`). The identifiable set comes from the data set whose
    poses separate the most parameters, then move the most joints through the most distinct poses
    (the first of those) unless ``ident`` is
    given; a data set that cannot identify it (a joint still in it alone, too few distinct poses) is
    named in ``problems`` and not converged, as is one whose poses cannot separate it (joints moved
    together: the set's column-scaled condition at its start beyond
    :data:`.selection.MAX_CONDITION`), and members that Gauss-Newton does not converge are
    fitted again by Levenberg-Marquardt, as in :func:`calibrate`; members whose fit ran where
    the set is not separable (an arm far from its file) are fitted again with the set
    identifiable at their fit (``rechosen``). A given ``ident`` is the caller's: only too few
    distinct poses are named, and there is neither retry. A data set whose solve gives
    non-finite values is reported (``nonfinite``, ``converged`` False) with ``x`` = 0, never NaN.
    A pose with no point measured (NaN), or a pose NaN in its top three rows, is left out of its
    data set's fits; a data set that never measured one of the points is named in ``problems``
    (that point's place cannot be estimated from it), and the other data sets are fitted as
    without it. Each member is judged as
    :func:`calibrate` judges its fit (``implausible``: the plausibility limits, and more outliers
    than ``max_outlier_fraction``); with ``strict`` any such member raises
    :class:`jaxcal.ImplausibleFitError` naming it."""
    devs = select_devices(devices)
    opts = make_options(options, kw, elimination=True)
    q, target, n_points = as_target(robot, q, measured, batched=True, position_only=position_only)
    layout = make_layout(robot, opts, n_points)
    R, K = q.shape[:2]
    if R == 0:
        raise DataError("no data sets: q and measured have R = 0 along their first axis", option="q")
    if ident is not None and tuple(ident.names) != tuple(layout.names()):
        raise DataError(
            f"ident is for parameters {ident.names[:3]}... ({len(ident.names)}), this calibration "
            f"has {layout.size}: pass the analysis of the same robot and options",
            option="ident",
        )
    q, target, masks, unfit = _lost_filled(q, target, n_points)
    copied = np.array([bool(u) for u in unfit])  # fitted on another data set's data: results discarded
    # robust, as calibrate: one wild row (a sentinel, an unreachable target) is the outliers' to name
    nominal_pos = core.nominal_positions(robot, q)
    check_units(robot, q, target, n_points, batched=True, model_positions=nominal_pos, robust=True)
    if opts.method in ELIMINATION_METHODS:
        return _elimination_batch(robot, q, target, n_points, layout, opts)
    cand = kinematic_set(opts, robot)
    wanted = list(layout.frames + layout.cameras) + [i for i in range(layout.n_kin) if i in cand.dh]
    wanted += list(layout.compliances) if cand.compliance else []
    check_enough_poses(K, layout, len(wanted) if K < 2 else 0)
    # a joint whose encoder only jitters is still, as calibrate takes it (core.still_span)
    still, distinct = np.ptp(q, axis=-2) <= core.still_span(robot), core.distinct_poses(q, core.same_pose(robot))
    check_enough_poses(K, layout, core.generic_rank(core.generic_model(robot, layout), layout, K, wanted))
    cfg = core.Config(layout, opts.method, opts.max_steps, opts.rtol, opts.atol, opts.loss, shared_data=False)
    nominal = core.broadcast_model(nominal_model(robot, layout), R)
    core.prepare_members(cfg, nominal, q, target, masks, memory_mb=opts.memory_mb, devices=devs)
    core.prepare_analysis(core.member(nominal, 0), layout, q[0])

    def start(masks):
        if not layout.frames:
            return nominal
        return core.start_models(robot.stripped(), layout, q, target, masks, shared=False)

    ref = start(masks)
    # the identifiable set from the data set that separates the most directions of the parameters
    # wanted, then moves the most joints through the most distinct poses: one degenerate data set
    # (a joint still, joints moved together) must not take parameters from the others
    N = core.scaled_normals(ref, layout, core.identification_poses(robot, q), wanted, opts.memory_mb, masks)
    counts = core.separable_counts(N, selection.MAX_CONDITION)
    r0 = int(np.lexsort((-distinct, still.sum(-1), -counts, copied))[0])
    J0 = core.analyse(core.member(ref, r0), layout, q[r0])[0]
    given_ident = ident
    if ident is None:  # on the poses it measured
        ident = core.identified(core.member(ref, r0), layout, q[r0], robot, J=J0, poses=masks[r0] > 0)
    # each data set's own lever, as calibrate gives it alone (the start models: the frames-only
    # fits of calibrate come later and move no lever a prior needs)
    lever = (
        core.levers(ref, layout, q, opts.memory_mb, masks) if cand.ridge_mm is not None else np.ones((R, layout.size))
    )
    prior = member_priors(layout, ident, cand, lever)
    # a given set is the caller's: only its count is judged, and a data set that cannot separate it
    # stays unconverged (Levenberg-Marquardt's damping would hold it and call it converged)
    mine = given_ident is None
    alone = (still & ~still[r0] & mine) | still.all(-1, keepdims=True)  # no joint moving: it identifies nothing
    measured = masks.sum(-1).astype(int)
    problems = _batch_problems(robot, alone, distinct, layout.rows, len(estimated(prior[0])), measured, np.ptp(q, -2))
    problems = tuple(u or p for u, p in zip(unfit, problems))
    if mine:  # poses that move every joint yet cannot separate the set estimated (joints moved together)
        sub = [k for k, i in enumerate(wanted) if i in set(ident.base)]
        tied = core.inseparable(N[:, sub][:, :, sub], selection.MAX_CONDITION)
        problems = tuple(p or (TIED if t else "") for p, t in zip(problems, tied))
    run = dict(J0=J0, memory_mb=opts.memory_mb, progress=progress, devices=devs, fallback=mine)
    given = opts.sigma_pos_mm is not None and (n_points or opts.sigma_rot_rad is not None)
    reweigh = n_points == 0 and not given and opts.method != "linear"  # as calibrate

    def stages(ref, masks, x0=None):  # frames only (unless nothing needs it), then the set
        sig = np.tile([1.0, 1.0], (R, 1))
        if layout.frames or not given:
            unit = np.repeat(core.weights_of(layout, np.array([core.UNIT_WEIGHTS])), R, 0)
            frames_only = np.repeat(prior_of(layout, ident, None, frames_only=True)[None], R, 0)
            a = core.run_members(cfg, ref, q, target, masks, unit, frames_only, **run, label="frames only")
            ref = a["model"]
            sig = core.sigmas_from(a["pos_err"], a["rot_err"], masks, n_points)
        sig = _given(sig, opts)
        w = core.weights_of(layout, sig)
        b = core.run_members(cfg, ref, q, target, masks, w, prior, opts.loss_scale, x0=x0, **run, label="calibrating")
        active = np.full(R, reweigh)
        for _ in range(REWEIGHTS) if reweigh else ():  # as calibrate, each member until its weights settle
            new = _given(core.robust_sigmas(b["pos_err"], b["rot_err"], masks, n_points), opts)
            active &= ~np.all(np.abs(np.log(new / sig)) < np.log(REWEIGHT_TOLERANCE), -1)
            if not active.any():
                break
            sig = np.where(active[:, None], new, sig)
            w = core.weights_of(layout, sig)
            again = core.run_members(
                cfg, ref, q, target, masks, w, prior, opts.loss_scale, x0=b["x"], **run, label="reweighted"
            )
            b = jax.tree.map(lambda old, n: np.where(_lead(active, np.ndim(n)), n, old), b, again)
        return ref, w, b

    ref_b, weights, b = stages(ref, masks)
    rechosen = np.zeros(R, bool)
    if mine:  # before the outliers, which a fit stopped at a point of the parameterisation would misjudge
        chunk = core.members_chunk(layout, R, K, opts.memory_mb, devs)  # the fits' own program

        def again(idx, priors):  # from each member's last fit
            data = (core.take(q, idx), core.take(target, idx), masks[idx], weights[idx], priors)
            return core.run_members(
                cfg, core.take(ref_b, idx), *data, opts.loss_scale, x0=b["x"][idx], chunk=chunk, **run,
                label="set chosen again",
            )  # fmt: skip

        sound = np.array([not p for p in problems])  # a data set that cannot identify the set is named
        prior_for = lambda r, i: prior_of(layout, i, cand, lever=lever[r])  # noqa: E731
        b, rechosen, prior = _rechosen(robot, layout, ident, q, masks, b, prior, prior_for, again, opts, sound)
    refit = lambda w, x0: core.run_members(  # noqa: E731
        cfg, ref_b, q, target, w, weights, prior, opts.loss_scale, x0=x0, **run, label="outliers"
    )
    det = outliers.found(b, refit, masks, target, opts)
    if det.flags.any() and not opts.keep_outliers:  # every data set again without its outliers
        kept = masks * ~det.flags
        # a member whose set was chosen again starts from its last fit: that set may be singular at the start
        _, _, b = stages(start(kept), kept, np.where(rechosen[:, None], b["x"], 0.0) if rechosen.any() else None)
        found = dict(poses=n_points == 0, sigmas=opts.outlier_sigmas, loss_scale=opts.loss_scale)
        det = outliers.assess(b, masks, outliers.position_rows(target), excluded=det.flags, **found)
    nonfinite = ~np.all(np.isfinite(b["x"]), axis=-1) & ~copied
    x = core.relative_x(robot, layout, b["model"]) if layout.frames else np.array(b["x"])
    if rechosen.any():  # a refit with another set can wander by whole turns: within half a turn, as calibrate
        idx = np.flatnonzero(rechosen)
        x[idx] = core.relative_x(robot, layout, core.wrapped(core.take(b["model"], idx), robot))
    x[nonfinite] = 0.0
    failed = nonfinite | np.array([bool(p) for p in problems])
    x[failed] = 0.0  # a data set that cannot identify its set estimated nothing, as estimated says
    ok = np.asarray(b["converged"]) & ~failed
    flags = det.flags & ~failed[:, None]  # a data set not fitted has no outliers to name
    share = flags.sum(-1) / np.maximum(masks.sum(-1), 1)  # of the poses it measured
    free = (np.asarray(prior) < PIN) & ~failed[:, None]
    kept = masks * ~flags if not opts.keep_outliers else masks
    why = list(_implausible(robot, opts, q, layout, x, b, kept.astype(bool), free, n_points, nonfinite))
    for r in np.flatnonzero((share > opts.max_outlier_fraction) & ~failed):  # as calibrate judges its outliers
        m = masks[r] > 0
        rot = None if n_points else np.degrees(np.asarray(b["rot_err"][r]))[m]
        pos = outliers.pose_position_mm(b["pos_err"][r])[m]
        many = outliers.too_many(
            flags[r][m], det.sigmas[r][m], pos, np.flatnonzero(m), opts.max_outlier_fraction, rotation_deg=rot
        )
        why[r] = "; ".join(w for w in (why[r], many) if w)
    why = tuple("" if c else w for c, w in zip(copied, why))
    if opts.strict and any(why):
        bad = [r for r, w in enumerate(why) if w]
        raise ImplausibleFitError(
            f"{len(bad)} of {R} data sets are not plausible calibrations (strict): data set {bad[0]}: {why[bad[0]]}"
            + (
                f"; and data sets {', '.join(map(str, bad[1:8]))}{', ...' if len(bad) > 8 else ''}"
                if len(bad) > 1
                else ""
            )
        )
    return BatchResult(
        x=x,
        converged=ok,
        num_steps=np.where(copied, 0, np.asarray(b["steps"])),
        identifiability=ident,
        layout=layout,
        method=opts.method,
        loss=opts.loss,
        outlier_mask=flags,
        degraded=(flags.any(-1) & (opts.keep_outliers and opts.loss == "l2")) | (share > opts.max_outlier_fraction),
        nonfinite=nonfinite,
        devices=tuple(describe(devs)),
        problems=problems,
        rechosen=rechosen,
        estimated=free,
        implausible=why,
    )


def _implausible(robot: Robot, opts: Options, q, layout: Layout, x, b, kept, free, n_points: int, nonfinite):
    """:attr:`BatchResult.implausible`: :func:`._plausibility.findings` of each member whose
    residual or parameters pass a limit (one vectorised screen over the members first)."""
    limits = plausibility.Thresholds.of(robot, opts, q)
    pos = np.where(kept[..., None], np.asarray(b["pos_err"]), np.nan)
    suspect = nonfinite | (core.nan_rms(pos, (1, 2)) > limits.residual_mm)
    if n_points == 0:
        rot = np.where(kept, np.asarray(b["rot_err"]), np.nan)
        suspect |= np.degrees(core.nan_rms(rot, 1)) > limits.rotation_deg
    units = np.array(layout.units())
    kin = np.zeros(layout.size, bool)
    kin[: layout.n_kin] = True
    x = np.where(kin & (units == "rad"), plausibility.wrap_angle(x), x)  # a whole turn is no change
    big = np.abs(np.where(free, x, 0.0))
    suspect |= np.any(kin & (units == "mm") & (big > limits.length_mm), -1)
    suspect |= np.any(kin & (units == "rad") & (big > limits.angle_rad), -1)
    suspect |= np.any(big[:, list(layout.cameras)] > limits.camera, -1) if layout.cameras else False
    out = [""] * len(x)
    for r in np.flatnonzero(suspect):  # few: the findings, in calibrate's words
        st = core.residual_stats(b["pos_err"][r], b["rot_err"][r], kept[r], n_points=n_points)
        found = plausibility.findings(st, x[r], layout, limits, free=tuple(np.flatnonzero(free[r])))
        out[r] = "; ".join(found)
    return tuple(out)


def _rechosen(
    robot: Robot, layout: Layout, ident: Identifiability, q, masks, b: dict, prior, prior_for, again, opts, sound
):  # fmt: skip
    """``(b, which, prior)``: the members whose fit ran where ``ident``'s set is not separable (an
    arm far from its file, :func:`._core.reidentified`) fitted again with the set identifiable at
    their fit (``prior_for(member, set)`` their rows of ``prior``; ``again(members, priors)``), as
    :func:`calibrate` does; among the ``sound`` members (a data set named in ``problems`` is not
    converged anyway)."""
    R = len(q)
    which = np.zeros(R, bool)
    sound = sound & np.all(np.isfinite(b["x"]), -1)
    far = core.singular_at_fit(b["model"], layout, q, ident.base, selection.MAX_CONDITION, opts.memory_mb, masks)
    idx, priors = [], []
    for r in np.flatnonzero(far & sound):  # rare: the members that ran there, each analysed alone
        qr = q[r][masks[r] > 0]  # the poses it measured
        found = core.reidentified(ident, core.member(b["model"], r), layout, qr, robot, selection.MAX_CONDITION)
        if found is not None:
            idx.append(r)
            priors.append(prior_for(r, found[0]))
    if not idx:
        return b, which, prior
    idx = np.array(idx)
    prior = np.array(prior, copy=True)
    prior[idx] = priors
    new = again(idx, prior[idx])
    which[idx] = True

    def merged(a, n):
        a = np.array(a)
        a[idx] = n
        return a

    return jax.tree.map(merged, b, new), which, prior


def _still_joints(robot: Robot, q) -> np.ndarray:
    """``(..., n)`` which joints never move over the poses ``q (..., K, n)``."""
    return np.ptp(np.asarray(q), axis=-2) <= core.joint_tolerance(robot)


def _lost_filled(q, target, n_points: int):
    """A batch's data with what was not measured made finite for the compiled solve, and the
    pose weights ``masks (R, K)``: a pose with no point is left out of its data set's fits (and
    holds a copy of one of its poses); a data set that never measured a point, or no pose, holds
    a sound data set's data, and the reason (``unfit``, "" for the others) makes it a problem,
    whose results are discarded."""
    R, K = q.shape[:2]
    masks, unfit = np.ones((R, K)), [""] * R
    if n_points:
        gone, unseen = lost_points(target)
    else:  # a pose not measured: NaN in its top three rows
        gone, unseen = np.isnan(target[..., :3, :]).all((-1, -2)), np.zeros((R, 0), bool)
    if not gone.any() and not unseen.any():
        return q, target, masks, unfit
    what = "point" if n_points else "pose"
    bad = unseen.any(-1) | gone.all(-1)
    for r in np.flatnonzero(bad):  # the few data sets that cannot be fitted
        points = ", ".join(str(int(j) + 1) for j in np.flatnonzero(unseen[r]))
        unfit[r] = f"point(s) {points} never measured" if not gone[r].all() else f"no {what} measured at any pose"
    if bad.all():
        raise DataError(f"measured: no data set can be fitted: data set 0: {unfit[0]}", option="measured")
    src = np.where(gone, np.argmax(~gone, axis=1)[:, None], np.arange(K))  # a lost pose: the first measured
    src[bad] = src[np.argmin(bad)]
    rows = np.where(bad, np.argmin(bad), np.arange(R))[:, None]
    masks = (~gone[rows[:, 0]]).astype(float)
    return q[rows, src], target[rows, src], masks, unfit


TIED = (
    "its poses do not separate the parameters the batch estimates (their column-scaled condition is beyond "
    f"{selection.MAX_CONDITION:.0e} at the start: joints moved together?); calibrate it alone for the set its poses "
    "identify"
)


def _batch_problems(robot: Robot, still, distinct, rows: int, needed: int, n_poses, span) -> tuple[str, ...]:
    """Why each data set cannot identify the ``needed`` parameters of the batch's set ("" where it
    can): the joints ``still (R, n)`` that never move in it alone (all of them: no joint moves;
    ``span (R, n)`` their spreads, an encoder's jitter named), or too few ``distinct`` poses among
    the ``n_poses (R,)`` it measured."""
    lim, unit = core.still_span(robot), ["rad" if t == "R" else "mm" for t in robot.joint_types]
    out = [""] * len(still)
    for r in np.flatnonzero(still.any(-1) | (distinct * rows < needed)):  # the data sets with a problem
        moves = not still[r].all()
        why = [
            f"joint {j + 1} ({robot.joint_names[j]}) never moves"
            + (f" beyond {lim[j]:.2g} {unit[j]}" if span[r, j] else "")
            for j in np.flatnonzero(still[r])
            if moves
        ]
        why += [] if moves else ["no joint moves"]
        if distinct[r] * rows < needed:
            eq, k = distinct[r] * rows, n_poses[r]
            why.append(f"{distinct[r]} distinct poses of {k} x {rows} rows = {eq} equations for {needed} parameters")
        out[r] = "; ".join(why)
    return tuple(out)


MORE_PAIRS = "(n_pairs of jaxcal.solvers.design_poses; --pairs of jaxcal reproduce)"
PAIRS_LOSE = "the elimination's pose pairs hold"


def _pairs_problems(plan, ident, ok, joint_types) -> tuple[str, ...]:
    """Where the robust elimination's pairs lose what the poses tell a least-squares fit (its
    base set, ``ident``): a plan that identifies fewer parameters (a pair whose poses barely
    differ in its joint; no result then), or, where the sweeps did not settle, a step that holds
    at 0 a column another step estimates (one pair per step on the paper's arm)."""
    gn_fixed = set(ident.fixed_names)
    if len(plan.identified) < ident.rank:
        held = [plan.names[j] for j in plan.fixed if plan.names[j] not in gn_fixed]
        return (
            f"{PAIRS_LOSE} {', '.join(held or [plan.names[j] for j in plan.fixed])} at 0, which these poses "
            f"identify ({len(plan.identified)} parameters by the pairs, {ident.rank} by method 'gn'): a pair "
            f"whose poses barely differ in its joint, or too few pairs per step; use method='gn', or a design "
            f"with more pairs {MORE_PAIRS}",
        ) * len(ok)
    lost = lambda st: [plan.names[j] for j in st.columns if j not in st.free and plan.names[j] not in gn_fixed]  # noqa: E731
    failing = [st for st in plan.steps if lost(st)]
    mixed = [f"step {st.joint} holds {', '.join(lost(st))}" for st in failing]
    # the steps difference poses of turning joints: a sliding joint's pairs may never separate it
    sliding = [str(st.joint) for st in failing if joint_types[st.joint - 1] == "P"]
    if sliding:
        why = (
            f"not converged where {'; '.join(mixed)} at 0, although these poses identify it: the sweeps then "
            f"need not settle, and joint(s) {', '.join(sliding)} slide (prismatic), where more pose pairs may not "
            "help; use method='gn'"
        )
    else:
        why = (
            f"not converged where {'; '.join(mixed)} at 0 for want of pose pairs, although these poses identify "
            f"it: the sweeps then need not settle; use a design with more pairs per step {MORE_PAIRS}, or "
            "method='gn'"
        )
    return tuple("" if k or not mixed else why for k in ok)


def _elimination_batch(robot, q, target, n_points, layout, opts) -> BatchResult:
    # the first of what it cannot do, named by its own option
    for given, option, why in (
        (n_points, "position_only", "full-pose measurements, not positions alone"),
        (layout.camera != "none", "camera", "full-pose measurements, not a camera model"),
        (layout.base, "estimate_base", "a known base frame, not one estimated"),
        (layout.tool, "estimate_tool", "a known tool frame, not one estimated"),
    ):
        if given:
            raise DataError(
                f"the elimination method needs {why} ({option}), or a least-squares method ('gn', 'lm')",
                option=option,
            )
    sp = opts.sigma_pos_mm or 1.0
    sr = opts.sigma_rot_rad or 1e-3
    x, ok, steps, plan = calibrate_design_batch(
        robot, q, target, sp, sr, literal=opts.method == "elimination-literal", max_steps=opts.max_steps, tol=opts.atol
    )
    x, ok = np.array(x), np.array(ok)
    nonfinite = ~np.all(np.isfinite(x), axis=-1)
    x[nonfinite] = 0.0
    ok[nonfinite] = False
    ident = core.base_set(core.analyse(Model(robot.stripped()), layout, q[0])[0], layout, robot)
    R, K = q.shape[:2]
    # judged on the first data set's poses, as the plan is: only where every data set has them (a
    # Monte Carlo study draws a design per robot); the literal variant solves each block whole
    if opts.method == "elimination" and np.all(q == q[:1]):
        problems = _pairs_problems(plan, ident, ok, robot.joint_types)
        ok &= ~np.array([w.startswith(PAIRS_LOSE) for w in problems])
    else:
        problems = ("",) * R
    return BatchResult(
        x=x,
        converged=ok,
        num_steps=np.asarray(steps),
        identifiability=ident,
        layout=layout,
        method=opts.method,
        loss=opts.loss,
        outlier_mask=np.zeros((R, K), bool),
        degraded=np.zeros(R, bool),
        nonfinite=nonfinite,
        devices=tuple(describe(select_devices(None))),  # the elimination design solve is not sharded
        problems=problems,
    )
