"""The real-data workflow (:func:`calibrate_data`): a calibration that chooses its own model and
says, from poses it never fitted, how well that model predicts new postures and postures beyond
the training ranges. The one behind ``jaxcal calibrate``.

## Model
``T(x, q) = B(x_b) · A_1(dh + dx_1) ... A_n(dh + dx_n) · X(x_t)`` (or points ``m_j`` on the
tool), the frames ``B0, X0`` corrected as :func:`jaxcal.error_model.perturb` does (docs/conventions.md), from
the closed-form guess of each training set
(:mod:`._initial`); joint compliances (:attr:`jaxcal.Robot.compliance`) and a camera model
(:mod:`jaxcal.camera`) where the candidates carry them.

## Stages
1. **Checks** (:func:`_prepare`): data, units, enough poses, the candidates and the folds.
2. **Frames** (:func:`_frames`): a frames-only fit (nominal kinematics, unit weights 1 mm : 1
   deg) on every training set and on all poses; its residual gives the weights (full poses: the
   rotation rows' at the noise's ratio of radians to millimetres, :func:`_weighed`).
3. **Outliers** (:func:`_outliers_found`): poses far beyond the noise of a flexible model fitted
   on all poses (:mod:`._outliers`) are left out of everything that follows; found again from
   the fit without them when they had inflated the noise weights
   (:data:`._outliers.REDETECT_SIGMA`).
4. **Selection** (:mod:`._selection`): on the problem linearised at the frames-only fit, every
   candidate is scored by held-out error on K-fold and range-end folds, the best (a simpler one
   within one standard error, and at least 1 %, winning) is chosen, and its parameters pruned
   while the score holds. Where that linearisation misses the final fit's residual
   (:data:`RELINEARISE`), or the final fit ran to where the parameters identifiable at the
   nominal are not separable (:func:`._core.reidentified`), or more are identifiable there and
   fit materially better (:func:`_wider`: then those identifiable there), stages 4-6 run again
   on the problem linearised at the final fit, each fit from its last.
5. **Held-out figures**: the selection is made again inside every outer training set (K-fold
   folds: new postures; range-end folds: postures beyond the training ranges), each choice
   fitted in full on its training set and scored on the poses held out (nested
   cross-validation, up to ``nested_max_poses`` poses).
6. **Final fit**: the chosen model on all poses; standard errors, plausibility, the report
   (:mod:`._report`).
"""

from __future__ import annotations

import dataclasses
import itertools

import jax
import numpy as np

from .._config import jit
from ..camera import CAMERA_MODELS, check_target_in_front
from ..camera import n_params as camera_size
from ..errors import DataError, warn_unusable
from ..model import Layout, Model, errors
from ..robot import Robot
from ..solvers import PIN
from . import _core as core
from . import _outliers as outliers
from . import _selection as selection
from ._checks import as_target, check_rigid_points, check_units, duplicate_rows_note
from ._options import Options, make_options
from ._param_sets import Candidate, parse_params
from ._report import DataCalibration, report_of
from ._single import (
    REWEIGHT_TOLERANCE,
    check_enough_poses,
    make_layout,
    nominal_model,
    prior_of,
    still_joint_notes,
)

DETECTION_PRIOR_MM = 1.0
"""The prior of the flexible model that outliers are found with (all parameters)."""


def fold_ids(n_poses: int, k: int, seed: int, groups=None) -> np.ndarray:
    """Fold index (0..k-1) of each pose: a seeded permutation cut into k nearly equal parts, the
    repeats of a posture (``groups``, one label per posture) in one fold
    (:func:`._selection.grouped_folds`)."""
    if not 2 <= k <= n_poses:
        raise DataError(f"folds must be between 2 and the number of poses ({n_poses}), got {k}", option="folds")
    g = np.arange(n_poses) if groups is None else np.asarray(groups)
    return selection.grouped_folds(np.random.default_rng(seed).permutation(n_poses), g, k)


@dataclasses.dataclass(frozen=True, eq=False)
class _Problem:
    """Stage 1: the checked data, the candidates and the folds."""

    robot: Robot
    opts: Options
    data: object
    q: np.ndarray
    target: np.ndarray
    n_points: int
    rows: np.ndarray
    """The data rows of the poses in the file."""
    layout: Layout
    candidates: list
    detector: Candidate
    """The flexible model outliers are found with."""
    ident: object
    cfg: core.Config
    run: dict
    held: np.ndarray
    """``(O, K)`` outer held-out sets: ``n_kfold`` K-fold sets, then the range-end sets."""
    n_kfold: int
    valid: np.ndarray
    """``(K,)`` the poses not found outliers."""
    nested: bool
    groups: np.ndarray
    """``(K,)`` one label per posture (:func:`._core.posture_ids`): repeats share a fold."""
    notes: tuple[str, ...] = ()
    """What the report should say about how the fit was made (:func:`_fitted`)."""
    prune: bool = True
    """Whether the chosen set is pruned (auto); off where pruning's linearisation failed
    (:func:`_prune_holds`)."""

    @property
    def masks(self) -> np.ndarray:
        """``(O + 1, K)`` training sets: every outer one, then all poses (outliers left out)."""
        return np.concatenate([~self.held, np.ones((1, len(self.q)), bool)]) & self.valid[None]

    @property
    def auto(self) -> bool:
        return self.opts.params.strip() == "auto"


# each compiled as one program: run op by op, every operation would be a program of its own to
# compile in each process
_errors = jit(errors)


def _compliant(robot: Robot, q, opts: Options) -> bool:
    """Whether the candidates may carry joint compliances: asked for, or (``auto``) a revolute
    joint's gravity moment varies over the data by more than 1 % of the reach."""
    if opts.compliance != "auto":
        return opts.compliance == "yes"
    tau = np.asarray(core.moments(robot.stripped(), q))
    return bool(np.ptp(tau, axis=0).max() > 0.01 * robot.reach(q))


def _candidates(robot: Robot, opts: Options, cameras, compliance: bool) -> tuple[list, Candidate]:
    """The candidates (every parameter set with each camera model) and the outliers' detector."""
    auto = opts.params.strip() == "auto"
    sets = parse_params(opts.params, robot, opts.ridge_mm, compliance=compliance and (auto or opts.compliance == "yes"))
    if auto and opts.compliance == "yes":  # asked for: every model that moves the kinematics carries them
        sets = [c for c in sets if c.compliance or not c.dh]
    cands = [
        dataclasses.replace(c, camera=m, name=f"{c.name}, camera {m}" if opts.camera == "auto" else c.name)
        for m in cameras
        for c in sets
    ]
    if not auto:
        return cands, cands[-1]
    flexible = parse_params("all", robot, DETECTION_PRIOR_MM, compliance=compliance)[0]
    return cands, dataclasses.replace(flexible, camera=cameras[-1])


def _solve(robot: Robot, layout: Layout, opts: Options, q, target, n_sets: int) -> tuple[core.Config, int]:
    """The solve every fit of the workflow runs (its configuration and members per call, for
    ``n_sets`` training sets at most), its compile and the analysis' started in the background
    meanwhile (:func:`._core.prepare_members`)."""
    cfg = core.Config(layout, opts.method, opts.max_steps, opts.rtol, opts.atol, opts.loss, shared_data=True)
    chunk = core.chunk_size(n_sets, len(q), layout, opts.memory_mb)
    nominal = core.broadcast_model(nominal_model(robot, layout), 1)
    core.prepare_members(cfg, nominal, q, target, np.ones((1, len(q))), chunk=chunk, memory_mb=opts.memory_mb)
    core.prepare_analysis(core.member(nominal, 0), layout, q)
    return cfg, chunk


def _prepare(robot: Robot, data, opts: Options, progress) -> _Problem:
    """Stage 1 (module docstring)."""
    if not (hasattr(data, "q") and hasattr(data, "measured")):  # a tuple of arrays, a file name
        raise DataError(
            f"data must be a jaxcal.Measurements (jaxcal.read_measurements(path, robot), or "
            f"jaxcal.Measurements(q, measured) from arrays), got {type(data).__name__}",
            option="data",
        )
    given = getattr(data, "rows", None)
    rows = np.arange(1, len(data.q) + 1) if given is None else np.asarray(given)
    numbers = tuple(getattr(data, "point_numbers", ()))  # the file's numbers name the points
    q, target, n_points = as_target(robot, data.q, data.measured, batched=False, rows=rows, numbers=numbers)
    if n_points:
        check_rigid_points(target, q, np.asarray(robot.revolute_mask, bool), numbers)
    if len(still_joint_notes(robot, q)) == robot.n_joints:
        raise DataError(
            f"no joint moves over the {len(q)} poses: every row is the same posture (rows {rows[0]}..{rows[-1]}), "
            f"from which neither the robot nor its frames can be calibrated; measure it in varied postures",
            option="data",
        )
    cameras = CAMERA_MODELS if opts.camera == "auto" else (opts.camera,)
    compliance = _compliant(robot, q, opts)
    candidates, detector = _candidates(robot, opts, cameras, compliance)
    layout = make_layout(robot, opts, n_points, camera=cameras[-1], compliance=compliance, point_numbers=numbers)
    if "quadratic" in cameras:
        check_target_in_front(target, "quadratic" + (" (tried by camera auto)" if opts.camera == "auto" else ""), rows)
    K, F = len(q), opts.folds
    groups = core.posture_ids(q, core.same_pose(robot))
    # more folds than poses is refused below, after whether the poses are enough at all
    fid = fold_ids(K, max(2, min(F, K)), opts.seed, groups)
    everything = np.ones(K, bool)
    ends = selection.range_end_held(core.identification_poses(robot, q), everything, groups=groups)  # moved joints
    held = np.concatenate([np.stack([fid == o for o in range(F)]), ends])
    union = set().union(*(c.dh for c in candidates))
    n_train = K - int(np.bincount(fid).max())
    wanted = lambda lay: list(lay.frames) + list(lay.cameras) + sorted(union)  # noqa: E731
    if compliance and opts.compliance == "auto" and n_train * layout.rows < 2 * (len(wanted(layout)) + layout.n_comp):
        # perhaps too few poses to tell a compliance from noise: decided on the rigid layout's rank
        # (the same columns), before either layout's programs are compiled
        rigid = dataclasses.replace(layout, n_comp=0)
        needed = core.generic_rank(core.generic_model(robot, rigid), rigid, K, wanted(rigid))
        if n_train * layout.rows < 2 * (needed + layout.n_comp):  # the rigid candidates alone
            candidates = [c for c in candidates if not c.compliance]
            detector = dataclasses.replace(detector, compliance=False)
            layout = rigid
    cfg, chunk = _solve(robot, layout, opts, q, target, len(held) + 1)
    needed = core.generic_rank(core.generic_model(robot, layout), layout, K, wanted(layout))
    notes = duplicate_rows_note(q, target, rows)
    if opts.params.strip() == "auto" and n_train * layout.rows < needed:  # a small session: what it can fit
        candidates, needed, small = _within_reach(robot, layout, K, n_train * layout.rows, candidates)
        notes += small
    check_enough_poses(int(core.distinct_poses(q, core.same_pose(robot))), layout, needed, K)
    m = -(-needed // layout.rows)  # the poses a training set needs, and so the data with F folds
    least = next(k for k in itertools.count(m + 1) if k - -(-k // F) >= m)
    postures = len(np.unique(groups))
    if postures < F:  # a fold would hold no posture: it trains on all and scores nothing
        enough = f"; {F}-fold cross-validation of {needed} parameters needs at least {least}"
        enough = enough if postures < least else ""
        raise DataError(
            f"folds ({F}) more than the distinct postures ({postures}; rows repeating a posture are one): use "
            f"fewer folds, or measure more postures{enough}",
            option="folds",
        )
    if n_train * layout.rows < needed:
        raise DataError(
            f"too few poses for {F}-fold cross-validation: training sets of {n_train} poses x "
            f"{layout.rows} rows = {n_train * layout.rows} equations for {needed} parameters; use fewer "
            f"folds or more poses (at least {least} with {F} folds)",
            option="folds",
        )
    ref = core.start_models(robot.stripped(), layout, q, target, everything[None], shared=True)
    J0, pos0 = core.analyse(core.member(ref, 0), layout, q)
    nominal_pos = core.nominal_positions(robot, q)
    check_units(robot, q, target, n_points, batched=False, model_positions=pos0, robust=True, also=nominal_pos)
    run = dict(J0=J0, chunk=chunk, memory_mb=opts.memory_mb, progress=progress, fallback=True)
    nested = (len(candidates) > 1 or opts.params.strip() == "auto") and K <= opts.nested_max_poses
    return _Problem(
        robot, opts, data, q, target, n_points, rows, layout, candidates, detector,
        core.identified(core.member(ref, 0), layout, q, robot, J=J0), cfg, run, held, F, everything, nested, groups,
        notes,
    )  # fmt: skip


def _within_reach(robot: Robot, layout: Layout, K: int, equations: int, candidates: list) -> tuple[list, int, tuple]:
    """``(candidates, parameters, notes)``: the candidates of ``params`` auto whose parameters a
    training set's ``equations`` can identify, the most any of them needs, and a note naming
    those left out; all of them and the simplest one's need (which the checks then refuse,
    saying what the data must give at least) when not even that one fits."""

    def columns(c):
        cams = list(layout.cameras)[: camera_size(c.camera)]  # the layout's are its largest camera model's
        comps = list(layout.compliances) if c.compliance else []
        return list(layout.frames) + cams + sorted(c.dh) + comps

    needs = core.generic_ranks(core.generic_model(robot, layout), layout, K, [columns(c) for c in candidates])
    kept = [c for c, n in zip(candidates, needs) if n <= equations]
    if not kept:
        return candidates, min(needs), ()
    left = [c.name for c, n in zip(candidates, needs) if n > equations]
    note = (
        f"params auto: a training set of cross-validation holds {equations} equations, fewer than "
        f"{'these candidates need' if len(left) > 1 else 'this candidate needs'} ({'; '.join(left)}): "
        f"{'they were' if len(left) > 1 else 'it was'} not tried; more poses let them be"
    )
    return kept, max(n for n in needs if n <= equations), (note,)


@dataclasses.dataclass(frozen=True, eq=False)
class _Frames:
    """Stage 2: the frames-only fit of every training set (:attr:`_Problem.masks`; the last: all
    poses)."""

    start: Model
    """The closed-form starting frames of each training set."""
    fit: dict
    """:func:`._core.run_members`'s output; ``model`` the frames-only models."""
    sig: np.ndarray
    """``(S, 2)`` noise weights (mm, rad) of each training set."""

    def member(self, i: int) -> Model:
        return core.member(self.fit["model"], i)


def _frames(p: _Problem) -> _Frames:
    """Stage 2 (module docstring): all poses first, then every training set from there."""
    masks = p.masks
    S, layout = len(masks), p.layout
    start = core.start_models(p.robot.stripped(), layout, p.q, p.target, masks, shared=True)
    unit = np.repeat(core.weights_of(layout, np.array([core.UNIT_WEIGHTS])), S, 0)
    pa = np.repeat(prior_of(layout, p.ident, None, frames_only=True)[None], S, 0)
    fw = masks.astype(float)
    last = [S - 1]
    a_all = core.run_members(
        p.cfg, core.take(start, last), p.q, p.target, fw[last], unit[last], pa[last], **p.run, label="frames only"
    )
    inner = np.arange(S - 1)
    a_sets = core.run_members(
        p.cfg,
        core.take(start, inner),
        p.q,
        p.target,
        fw[inner],
        unit[inner],
        pa[inner],
        x0=core.relative_x(core.take(start, inner), layout, a_all["model"]),
        **p.run,
        label="frames only, training sets",
    )
    fit = jax.tree.map(lambda u, v: np.concatenate([u, v]), a_sets, a_all)
    sig = core.sigmas_from(fit["pos_err"], fit["rot_err"], masks, p.n_points)
    if p.opts.sigma_pos_mm is not None:
        sig[:, 0] = p.opts.sigma_pos_mm
    if p.opts.sigma_rot_rad is not None:
        sig[:, 1] = p.opts.sigma_rot_rad
    return _Frames(start, fit, sig)


def _outliers_found(p: _Problem, fr: _Frames) -> outliers.Detection:
    """Stage 3 (module docstring): the detector fitted on all poses, then :func:`._outliers.detect`;
    again with the noise it found as the weights while the prior held the fit
    (:data:`._outliers.REWEIGHT_SHARE`)."""
    lev = selection.lever(core.analyse(fr.member(-1), p.layout, p.q)[0], p.n_points)

    def prior_mm(s):
        return prior_of(p.layout, p.ident, dataclasses.replace(p.detector, ridge_mm=s), lever=lev)[None]

    prior = prior_mm(p.detector.ridge_mm)
    ref = core.take(fr.fit["model"], [len(fr.sig) - 1])
    mask = p.valid[None].astype(float)

    def detected(sig, unmask=False):
        weights = core.weights_of(p.layout, sig)

        def refit(w, x0=None):
            return core.run_members(
                p.cfg, ref, p.q, p.target, w, weights, prior, p.opts.loss_scale, x0=x0, **p.run, label="outliers"
            )

        det = outliers.found(refit(mask), refit, mask.astype(bool), p.target, p.opts, unmask=unmask)
        return dataclasses.replace(det, noise=det.scale * sig)  # mm, rad: the weights of this detection

    sig = fr.sig[[-1]]
    det = detected(sig, unmask=True)  # the detections at the noise found start from its fit: looked at once
    # noise given, or a loss scale that sets the noise found: nothing to learn by detecting again
    given = p.opts.sigma_pos_mm is not None or p.opts.sigma_rot_rad is not None or p.opts.loss_scale is not None
    loose = max(p.detector.ridge_mm or 0.0, float(sig[0, 0]))
    far = p.detector.ridge_mm is not None and loose > p.detector.ridge_mm
    if not given and far and not det.noise[0, 0] < outliers.REWEIGHT_SHARE * sig[0, 0]:
        # an arm far from its nominal (its frames-only residual, the weights, far above the prior):
        # the prior holds the detector where the data would not; loosened to the weights' scale
        tight, prior = prior, prior_mm(loose)
        again = detected(sig, unmask=True)
        if again.noise[0, 0] < outliers.REWEIGHT_SHARE * det.noise[0, 0]:
            det = again
        else:  # the residual is not the prior's doing: the first detection stands
            prior = tight
    for k in range(0 if given else outliers.REWEIGHTS):
        share = outliers.REWEIGHT_SHARE if k == 0 else outliers.REFINE_SHARE
        if not det.noise[0, 0] < share * sig[0, 0]:
            break
        again = detected(det.noise)
        if not again.noise[0, 0] < share * det.noise[0, 0]:
            break  # the prior was not what kept the residual up: the detection before stands
        sig, det = det.noise, again
    return det


@dataclasses.dataclass(frozen=True, eq=False)
class _Selected:
    """A selection (:func:`_select`) as the fits need it."""

    choice: selection.Choice
    candidate: Candidate
    prior: np.ndarray
    """``(m,)`` prior weights for the full fit, :data:`PIN` outside the chosen parameters."""
    free: np.ndarray
    """``(C, m)`` every candidate's free parameters; ``priors (C, m)`` their prior weights."""
    priors: np.ndarray
    lever: np.ndarray


def _select(p: _Problem, lin: selection.Linear, J, train, seed: int) -> _Selected:
    """Stage 4 on the poses ``train``: score the candidates, choose one and prune it (auto)."""
    lev = selection.lever(J[train], p.n_points)
    full = np.stack([prior_of(p.layout, p.ident, c, lever=lev) for c in p.candidates])
    free = full < PIN
    priors = np.where(free, full, 0.0)
    penalised = np.zeros(p.layout.size, bool)
    penalised[: p.layout.n_kin] = True
    penalised[list(p.layout.compliances)] = True
    rule = selection.Rule.of(lin, core.identification_poses(p.robot, p.q), train, p.opts.folds, seed, p.groups)
    # a point these poses never see (a marker seen at a few poses, all held out) moves nothing
    # here: held, not a singular column that fails every candidate
    free &= (np.diag(rule.A_all) > 0)[None]
    complexity = [c.complexity for c in p.candidates]
    ch = selection.select(lin, rule, free, priors, complexity, penalised & (p.auto and p.prune))
    if ch.index < 0:
        why = "; ".join(f"{c.name}: {selection.failure(k)}" for c, k in zip(p.candidates, ch.conditions))
        raise DataError(
            f"no candidate parameter set could be fitted ({why}); try a smaller set (params), or more or more "
            f"varied poses",
            option="params",
        )
    prior = np.where(ch.free, priors[ch.index], PIN)
    return _Selected(ch, p.candidates[ch.index], prior, free, priors, lev)


RELINEARISE = 0.2
"""When the problem linearised at the frames-only fit misses the final fit's weighted residual by
more than this share of it (nominal errors large for the noise: tenths of a degree at 0.02 mm, or
any on noise-free data), the selection is made again on the problem linearised at that fit."""


def _linear(p: _Problem, model: Model, sig, x=None) -> tuple[selection.Linear, np.ndarray]:
    """The problem linearised at ``model`` (Stage 4), in the parameters of the frames-only fit of
    all poses: ``x`` is ``model`` relative to that fit (its priors stay centred on the nominal)."""
    J = core.analyse(model, p.layout, p.q)[0]
    r = np.asarray(_errors(model, p.q, p.target))
    if x is not None:
        r = r + np.einsum("krm,m->kr", J, np.asarray(x))
    return selection.linearise(J, r, core.weights_of(p.layout, sig)[0], p.n_points), J


def _chosen(p: _Problem, fr: _Frames, lin: selection.Linear, J, x0=None):
    """Stages 4-6: the choice on all poses and inside every outer training set, each fitted in
    full (the last member: all poses) from the frames-only fits, or from ``x0 (S, m)``."""
    opts = p.opts
    final = _select(p, lin, J, p.valid, opts.seed)
    train = p.masks[:-1]
    per_fold = [_select(p, lin, J, train[o], opts.seed + 1 + o) if p.nested else final for o in range(len(train))]
    members = per_fold + [final]
    fits = core.run_members(
        p.cfg,
        fr.fit["model"],
        p.q,
        p.target,
        p.masks.astype(float),
        core.weights_of(p.layout, fr.sig),
        np.stack([s.prior for s in members]),
        opts.loss_scale,
        x0=x0,
        **p.run,
        label="held-out and final fits",
    )
    return final, per_fold, fits


def _linear_gap(p: _Problem, lin: selection.Linear, sig, fits) -> float:
    """How far the linearised problem misses the weighted residual of the final fit (all poses) at
    that fit's parameters, as a share of that residual (RMS over the poses kept)."""
    model, x = core.member(fits["model"], -1), np.asarray(fits["x"][-1])
    actual = np.asarray(_errors(model, p.q, p.target)) * core.weights_of(p.layout, sig)[0]
    missed = actual - (lin.r - np.einsum("krm,m->kr", lin.J, x))
    ok = lin.seen & p.valid[:, None] & np.isfinite(actual)
    return float(np.sqrt(np.mean(missed[ok] ** 2) / max(np.mean(actual[ok] ** 2), 1e-300)))


def calibrate_data(robot: Robot, data, options: Options | None = None, /, *, progress=None, **kw) -> DataCalibration:
    """Calibrate from measured data: choose the model, estimate it, and measure how well it predicts
    poses it was not fitted on (module docstring).

    **Arguments**: ``data`` a :class:`jaxcal.Measurements` (from :func:`jaxcal.read_measurements`,
    or built from arrays); options as :class:`jaxcal.Options` or keywords, the defaults shared
    with :func:`calibrate`. ``progress(done, total, stage)`` is called as fits complete.

    **Returns** a :class:`DataCalibration` whose ``report`` (:func:`._report.report_of`) holds
    the held-out figures ``heldout_rms_mm`` (new postures) and ``extrapolation_rms_mm`` (postures
    beyond the training ranges), the frames-only ones, ``choice``, ``selection`` (the parameters
    kept and why the others were not), ``cv`` (every candidate's score), ``parameters`` (values,
    standard errors, units), ``training_ranges``, ``outliers`` and the rest listed in
    docs/conventions.md. Training figures are over the poses not found outliers; held-out
    figures over those and the outliers that lie together in one part of a joint's range.
    """
    opts = make_options(options, kw, camera_auto=True)
    if opts.params == "auto" and opts.ridge_mm is not None:  # else ignored without a word
        raise DataError(
            f"ridge_mm {opts.ridge_mm:g}: a prior for an explicit params set (such as params='all'); params 'auto' "
            "chooses its prior (0.3, 1, 3 mm or none) by cross-validation",
            option="ridge_mm",
        )
    p = _prepare(robot, data, opts, progress)
    fr = _frames(p)
    if not opts.keep_outliers:
        res = report_of(*_left_out(p, fr))
    else:
        # named as without the option (its detection and second look), then every pose fitted
        plain = _left_out(dataclasses.replace(p, opts=dataclasses.replace(opts, keep_outliers=False)), fr)
        named = ~plain[0].valid
        if not named.any():  # nothing left out: its fits are every pose's
            res = report_of(dataclasses.replace(plain[0], opts=opts), *plain[1:], named=named)
        else:
            fr, p, lin, final, per_fold, fits = _weighed_fits(p, fr)
            res = report_of(p, fr, plain[2], lin, final, per_fold, fits, named=named)
    warn_unusable(res.report["converged"], res.report["implausible"])
    return res


def _left_out(p: _Problem, fr: _Frames):
    """Stages 3-5: the outliers found (:func:`_outliers_found`) and left out, the fits without
    them (:func:`_weighed_fits`), and the poses the calibrated model predicts taken back (the
    second look). Returns :func:`._report.report_of`'s arguments."""
    nominal_set = p.ident
    det = _outliers_found(p, fr)
    if det.flags.any():  # everything again without them
        first, p = fr, dataclasses.replace(p, valid=~det.flags[0])
        fr = _frames(p)
        if fr.sig[-1, 0] < outliers.REDETECT_SIGMA * first.sig[-1, 0]:  # gross outliers set the weights: once more
            gross = outliers.gross(det)[0]
            alone = None
            if gross.any() and (gross != det.flags[0]).any():  # the gross ones alone may explain it
                alone = _frames(dataclasses.replace(p, valid=~gross))
                alone = alone if alone.sig[-1, 0] < outliers.REDETECT_SIGMA * first.sig[-1, 0] else None
            if alone is not None:  # the outliers of the data without the gross ones, and those
                det = _outliers_found(dataclasses.replace(p, valid=~gross), alone)
                det = dataclasses.replace(det, flags=det.flags | gross[None])
            else:
                det = _outliers_found(dataclasses.replace(p, valid=np.ones(len(p.q), bool)), fr)
            p = dataclasses.replace(p, valid=~det.flags[0])
            fr = _frames(p)
    fr, p, lin, final, per_fold, fits = _weighed_fits(p, fr)
    # poses the detector's model could not fit but the calibrated one predicts; each refit predicts
    # the poses still left out anew, so it looks again (the poses kept only grow: it ends)
    while (back := _readmitted(p, fr, final, fits)).any():
        p = dataclasses.replace(p, valid=p.valid | back)
        # a set chosen at the fit may be singular at the nominal: from the last fit
        fr, p, lin, final, per_fold, fits = _weighed_fits(
            p, _frames(p), fits["x"] if p.ident is not nominal_set else None
        )
    return p, fr, det, lin, final, per_fold, fits


def _weighed(p: _Problem, fr: _Frames, fits=None) -> _Frames:
    """``fr`` with, on full poses, the rotation rows weighted at the noise's ratio of radians to
    millimetres and the position rows' weight kept. The frames-only residual's ratio is the arm's
    errors', not the noise's: by it the rotation rows would count too little or too much, and the
    standard errors, one variance pooled over both, would miss. Its scale is what the priors are
    measured against (docs/conventions.md). The noise: the residual of ``fits`` (each training set
    its own, :func:`._core.robust_sigmas`), or of one linear step with every identifiable
    parameter from the frames-only fit of all poses."""
    if p.n_points or p.opts.sigma_rot_rad is not None or p.opts.method == "linear":
        return fr
    if fits is not None:
        noise = core.robust_sigmas(fits["pos_err"], fits["rot_err"], p.masks, p.n_points)
    else:  # the step's weighted residual back in mm and rad, each pose's norms as the fits give them
        res = _stepped(p, _linear(p, fr.member(-1), fr.sig[[-1]])[0], p.ident.base)
        pos, rot = (np.linalg.norm(res[:, k : k + 3], axis=1) * fr.sig[-1, i] for i, k in enumerate((0, 3)))
        noise = core.robust_sigmas(pos[None, :, None], rot[None], p.valid[None], p.n_points)
    sig = fr.sig.copy()
    sig[:, 1] = np.maximum(sig[:, 0] * noise[:, 1] / np.maximum(noise[:, 0], 1e-300), core.SIGMA_FLOOR[1])
    return dataclasses.replace(fr, sig=sig)


REWEIGH_PASSES = 2
"""Full poses: how many times the rotation rows' weight is taken again from the calibrated fits
(:func:`_weighed`) while it moves by more than :data:`._single.REWEIGHT_TOLERANCE`: a linear step
from the frames-only fit misses the noise where the nominal's errors are large for it. Each pass
runs the selection and every fit again."""


def _weighed_fits(p: _Problem, fr: _Frames, x0=None):
    """:func:`_fitted` with the rotation rows weighted at the noise's ratio (:func:`_weighed`):
    ``(fr, p, lin, final, per_fold, fits)``, ``fr`` with the weights the fits used."""
    fr = _weighed(p, fr)
    p, *out = _fitted(p, fr, x0)
    for _ in range(REWEIGH_PASSES):
        new = _weighed(p, fr, out[-1])
        if np.all(np.abs(np.log(new.sig / fr.sig)) < np.log(REWEIGHT_TOLERANCE)):
            break
        fr = new
        p, *out = _fitted(p, fr, out[-1]["x"])
    return fr, p, *out


def _fitted(p: _Problem, fr: _Frames, x0=None):
    """Stages 4-6 on the problem linearised at the frames-only fit; again where the final fit ran
    to where the nominal's base set is singular, with the set identified there
    (:func:`._core.reidentified`), and at the final fit while the linearisation misses it
    (:data:`RELINEARISE`). The fits start from the frames-only fits, or from ``x0 (S, m)`` (a set
    chosen at an earlier fit may be singular at the nominal). Returns the problem with the base
    set it ended with."""
    sig = fr.sig[[-1]]
    lin, J = _linear(p, fr.member(-1), sig)
    final, per_fold, fits = _chosen(p, fr, lin, J, x0)
    chooses = len(p.candidates) > 1 or p.auto  # a fixed set has nothing the linearisation decides
    relinearised = reidentified = 0
    while True:  # every refit is checked again; at most two passes of each kind
        fit = core.member(fits["model"], -1)
        again = None
        if reidentified < 2:
            again = core.reidentified(p.ident, fit, p.layout, p.q, p.robot, selection.MAX_CONDITION)
        # a fixed set has nothing the linearisation decides: never pending
        pending = chooses and again is None and _linear_gap(p, lin, sig, fits) > RELINEARISE
        gap = pending and relinearised < 2 * chooses
        if again is None and not pending and reidentified < 2:
            # a wider set only once the choice was made where the fit is: a fit held by a prior the
            # linearisation far from it chose leaves a residual any set cuts
            again = _wider(p, fit, sig)
        if again is not None:
            reidentified += 1
            p = dataclasses.replace(p, ident=again[0], notes=p.notes + (again[1],))
        elif gap:
            relinearised += 1
        else:
            break
        lin, J = _linear(p, fit, sig, fits["x"][-1])
        final, per_fold, fits = _chosen(p, fr, lin, J, fits["x"])  # each from its last fit
    if p.prune and final.choice.pruned and not (held := _prune_holds(p, fr, final, fits))[0]:
        names = p.layout.names()
        dropped = ", ".join(names[i] for i, *_ in final.choice.pruned)
        them = "it" if len(final.choice.pruned) == 1 else "them"
        p = dataclasses.replace(
            p, prune=False, notes=p.notes + (
                f"not pruned: the selection would drop {dropped} from {final.candidate.name}, which the linearised "
                f"problem judged of no use, but fitted in full the model without {them} leaves {held[1]:.3g} times "
                f"the residual of the model with {them} (an arm whose errors are not small for its linearisation)",
            ),
        )  # fmt: skip
        lin, J = _linear(p, core.member(fits["model"], -1), sig, fits["x"][-1])
        final, per_fold, fits = _chosen(p, fr, lin, J, fits["x"])
    return p, lin, final, per_fold, fits


PRUNE_MISS = 1.5
"""A pruned set whose full fit leaves more than this many times the weighted RMS residual of the
chosen set unpruned (fitted in full from the same start) is not kept: the linearisation that
judged the dropped parameters useless does not hold where the arm is."""


def _prune_holds(p: _Problem, fr: _Frames, final: _Selected, fits) -> tuple[bool, float]:
    """``(holds, ratio)``: the chosen set fitted in full on all poses without its pruning, from the
    pruned fit, and the ratio of the pruned fit's weighted RMS residual to that fit's. Judged only
    where both fits converged: one stopped short compares where it stopped, not the sets."""
    c = final.choice.index
    prior = np.where(final.free[c], final.priors[c], PIN)[None]
    last = len(p.masks) - 1
    full = core.run_members(
        p.cfg, core.take(fr.fit["model"], [last]), p.q, p.target, p.masks[-1:].astype(float),
        core.weights_of(p.layout, fr.sig[-1:]), prior, p.opts.loss_scale, x0=np.asarray(fits["x"])[-1:], **p.run,
        label="the chosen set unpruned",
    )  # fmt: skip
    ok = p.valid

    def rms(norms):
        return float(np.sqrt(np.nanmean(np.asarray(norms)[ok] ** 2)))

    ratio = rms(np.asarray(fits["norms"])[-1]) / max(rms(full["norms"][0]), 1e-300)
    both = bool(np.asarray(fits["converged"])[-1]) and bool(full["converged"][0])
    return not (both and ratio > PRUNE_MISS), ratio


WIDER_SHARE = 0.5
"""A larger set identifiable at the fit than at the nominal is taken when one linear step with it
leaves less than this share of the weighted residual that the nominal's set leaves: a gain that
no tilt of the axes within the noise gives."""


def _stepped(p: _Problem, lin: selection.Linear, base) -> np.ndarray:
    """``(K, rows)`` the weighted residual of the poses kept after one linear step in the
    parameters ``base`` (0 where a row is not observed or its pose left out)."""
    ok = lin.seen & p.valid[:, None]
    A = np.where(ok[..., None], lin.J, 0.0)[..., list(base)].reshape(-1, len(base))
    b = np.where(ok, lin.r, 0.0).ravel()
    return (b - A @ np.linalg.lstsq(A, b, rcond=None)[0]).reshape(ok.shape)


def _wider(p: _Problem, fit: Model, sig):
    """The base set identified at the final fit and a note, when it is larger than the nominal's and
    fits materially better (:data:`WIDER_SHARE`): a length held because two axes are parallel in
    the robot's file, while the arm's are tilted by degrees. ``None`` otherwise. Only here, where
    the model is chosen from the data; :func:`jaxcal.calibrate` fits the set the nominal gives."""
    lin, J = _linear(p, fit, sig)
    again = core.identified(fit, p.layout, p.q, p.robot, J=J)
    if again.rank <= p.ident.rank:
        return None
    if not core.scaled_condition(np.asarray(J).reshape(-1, p.layout.size), again.base) <= selection.MAX_CONDITION:
        return None  # identifiable, but not separable as the selection asks
    share = np.sum(_stepped(p, lin, again.base) ** 2) / max(np.sum(_stepped(p, lin, p.ident.base) ** 2), 1e-300)
    if not share < WIDER_SHARE:
        return None
    names = p.layout.names()
    freed = [names[i] for i in again.base if i not in p.ident.base]
    return again, (
        f"the parameters estimated were chosen again at the fit: {', '.join(freed)}, held at the nominal "
        f"model (axes parallel in the robot's file), {'is' if len(freed) == 1 else 'are'} identifiable at "
        f"the fit, where {'it cuts' if len(freed) == 1 else 'they cut'} the residual a step leaves to "
        f"{share:.0%}, so {'it is' if len(freed) == 1 else 'they are'} estimated"
    )


def _readmitted(p: _Problem, fr: _Frames, final: _Selected, fits) -> np.ndarray:
    """``(K,)`` the poses left out as outliers that the final model, fitted without them, predicts
    within the outlier threshold, each in the spread of its own prediction
    (:func:`_prediction_spread`): the detector's model (held by its prior) could not fit an arm far
    from its nominal, or a posture alone at the end of a joint's range, and its residual made clean
    poses look gross."""
    if p.valid.all():
        return np.zeros(len(p.q), bool)
    fin = {k: np.asarray(fits[k])[-1:] for k in ("pos_norms", "rot_norms")}  # all poses' fit
    det = outliers.judged(fin, p.target, p.n_points, p.opts)
    return ~p.valid & ~(det.sigmas[0] > det.threshold[0] * _prediction_spread(p, fr, final, fits))


def _prediction_spread(p: _Problem, fr: _Frames, final: _Selected, fits) -> np.ndarray:
    """``(K,)`` each pose's prediction error in units of the noise of its rows, ``sqrt(1 + h_k)``,
    ``h_k`` the mean over its rows of ``J_k C J_k^T``, ``C`` the final fit's parameter covariance
    per unit noise (its weighted normal equations over the poses it was fitted on, with its
    priors): a posture the other poses barely constrain is predicted only as well as the
    parameters it alone pins down are known, so a miss beyond the noise alone is no gross error."""
    lin, _ = _linear(p, core.member(fits["model"], -1), fr.sig[[-1]])
    free = final.prior < PIN
    A = selection.sums(lin, p.valid[None].astype(float))[0][0]
    N = A[np.ix_(free, free)] + np.diag(final.prior[free] ** 2)
    J = lin.J[:, :, free]
    h = np.einsum("kri,ij,krj->kr", J, np.linalg.pinv(N), J)
    return np.sqrt(1.0 + h.sum(1) / np.maximum(lin.seen.sum(1), 1))
