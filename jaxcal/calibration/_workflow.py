"""The real-data workflow (:func:`calibrate_data`): a calibration with honest held-out
validation, the one behind ``jaxcal calibrate``.

## Model
``T(x, q) = exp(xi_b) B0 · A_1(dh + dx_1) ... A_n(dh + dx_n) · X0 exp(xi_t)`` (or points ``m_j``
on the tool) with ``B0, X0`` from the closed-form guess of each training set
(:mod:`._initial`); a camera model (:mod:`jaxcal.camera`) when asked.

## Stages
A frames-only fit (nominal DH, unit weights 1 mm : 1 deg) on every training set gives its
starting frames and its noise weights (the RMS per coordinate and per axis); then every
candidate parameter set (:func:`parse_params`) is fitted on every training set from there, with
those weights. All of it is one compiled solve (:mod:`._core`).

## Outliers
Every training set (and all poses) finds its outliers on its own (:mod:`._outliers`, with the
candidate that fits its poses best); then both stages run again with them left out. The
held-out and training figures leave out the poses flagged on all poses; the report names them.

## Cross-validation
Folds are a seeded permutation of the poses cut into ``folds`` nearly equal parts. Each
candidate is fitted on ``folds - 1`` folds and evaluated on the one held out; the held-out
position errors of all folds are pooled into an RMS. The chosen candidate has the lowest pooled
held-out RMS (a simpler candidate within 1 % wins) and is refitted on all poses. Choosing the
best of several candidates on the same folds is optimistic, so the reported ``heldout_*``
figures come from **nested** cross-validation: inside each training set the candidate is chosen
again by an inner cross-validation, then evaluated on the outer held-out fold. Above
``nested_max_poses`` poses the figures are plain K-fold (the report says which).
"""

from __future__ import annotations

import dataclasses
import json

import jax
import numpy as np

from ..camera import CAMERA_MODELS, check_target_in_front
from ..camera import n_params as camera_size
from ..errors import DataError
from ..model import Layout, Model, measured_robot, observed
from ..robot import Robot
from . import _core as core
from . import _outliers as outliers
from ._checks import as_target, check_units
from ._options import Options, make_options
from ._param_sets import Candidate, parse_params
from ._single import check_enough_poses, estimated, judge, make_layout, nominal_model, prior_of, still_joint_notes


def fold_ids(n_poses: int, k: int, seed: int) -> np.ndarray:
    """Fold index (0..k-1) of each pose: a seeded permutation cut into k nearly equal parts."""
    if not 2 <= k <= n_poses:
        raise DataError(f"folds must be between 2 and the number of poses ({n_poses}), got {k}", option="folds")
    out = np.empty(n_poses, dtype=np.int64)
    out[np.random.default_rng(seed).permutation(n_poses)] = np.arange(n_poses) % k
    return out


def choose(scores: list[float], candidates) -> int:
    """Lowest score; a simpler candidate (fewer free parameters, stronger prior) within 1 % wins.
    A non-finite score (a fit that failed) never wins; if every score is, that is an error."""
    scores = [s if np.isfinite(s) else np.inf for s in scores]
    best = min(scores)
    if not np.isfinite(best):
        raise DataError(
            f"every candidate parameter set ({', '.join(c.name for c in candidates)}) failed to fit "
            f"(non-finite held-out errors); the data or the camera model may be degenerate"
        )
    ok = [i for i, s in enumerate(scores) if s <= 1.01 * best]
    return min(ok, key=lambda i: candidates[i].complexity)


def fit_failure(converged, finite, steps, max_steps: int, condition) -> str | None:
    """Why a candidate's cross-validation fits failed (``None`` when all converged): how many
    gave non-finite parameters (with ``condition()``, the condition number of its free
    parameters at the start) and how many stopped short of the tolerances."""
    converged, finite, steps = np.asarray(converged), np.asarray(finite), np.asarray(steps)
    n, why = len(converged), []
    if not finite.all():
        why.append(
            f"non-finite parameters in {int(np.sum(~finite))} of {n} fits (the normal equations were singular; "
            f"condition number {condition():.3g} of its free parameters at the start)"
        )
    short = ~converged & finite
    if short.any():
        limit = int(np.sum(short & (steps >= max_steps)))
        why.append(
            f"no convergence in {int(np.sum(short))} of {n} fits"
            + (f" ({limit} reached max_steps {max_steps})" if limit else "")
        )
    return "; ".join(why) or None


def _rms(v) -> float:
    """RMS of the finite values (a lost point is NaN)."""
    v = np.asarray(v)
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(np.square(v)))) if np.size(v) else float("nan")


def _max(v) -> float:
    v = np.asarray(v)
    v = v[np.isfinite(v)]
    return float(v.max()) if v.size else float("nan")


def _median_pose(pe) -> float:
    """Median over poses of each pose's RMS over its points (``pe (K, M)``, NaN: lost)."""
    pe = np.asarray(pe)
    return float(np.median(np.sqrt(np.nanmean(pe**2, -1)))) if len(pe) else float("nan")


def frame_doc(T) -> dict:
    """A frame as ``xyz_mm`` and roll-pitch-yaw ``rpy_deg`` (fixed axes x-y-z; at pitch ±90 deg,
    the robot files' convention of :func:`jaxcal.lie.matrix_to_rpy`, without a warning)."""
    from ..lie import matrix_to_rpy

    T = np.asarray(T)
    return {
        "xyz_mm": [float(v) for v in T[:3, 3]],
        "rpy_deg": [float(v) for v in np.degrees(np.asarray(matrix_to_rpy(T[:3, :3])))],
    }


@dataclasses.dataclass(frozen=True, eq=False)
class DataCalibration:
    """What :func:`calibrate_data` returns (lengths mm, angles rad unless named)."""

    model: Model
    """The calibrated model, fitted on all poses with the chosen parameter set."""
    nominal: Robot
    choice: Candidate
    report: dict
    """JSON-ready: everything ``jaxcal calibrate --json`` writes (see :func:`calibrate_data`)."""
    per_pose: dict
    """Per pose: ``rows`` (data rows), position errors (mm) ``heldout``, ``train``,
    ``frames_only_heldout``, ``frames_only_train`` (``(K, M)`` for several points), rotation
    errors (deg) ``*_rot``; ``frames_only``: the frames-only robot."""
    deltas: dict
    """name -> (value, standard error, unit) of every estimated parameter (DH errors relative to
    the nominal table; frame twists relative to the closed-form guess)."""
    covariance: np.ndarray | None = None
    """``(m, m)`` covariance of the final fit's parameters, named by ``layout.names()`` (mm, rad;
    0 where a parameter is held), whose diagonal gives the standard errors of :attr:`deltas`."""
    layout: Layout | None = None
    """The parameters of :attr:`covariance` (the largest camera model tried)."""

    @property
    def robot(self) -> Robot:
        return measured_robot(self.model)

    @property
    def cv_table(self) -> list:
        return self.report["cv"]

    def to_json(self) -> str:
        return json.dumps(self.report, indent=2)


def _layout_for(robot, opts, n_points, cameras) -> Layout:
    return make_layout(robot, opts, n_points, camera=cameras[-1])


@dataclasses.dataclass(frozen=True, eq=False)
class _Fits:
    """Every fit of the workflow on one set of training masks (:func:`_stages`); members of a
    stage: the training sets (``masks[:-1]``), then all poses."""

    ref: Model
    """The closed-form starting frames of each training set."""
    a: dict
    """Stage A, frames only: ``x``, ``converged``, ``pos_err``, ``rot_err`` per training set."""
    refB: Model
    """Stage A's models: the reference of stage B."""
    sig: np.ndarray
    """``(S, 2)`` noise weights (mm, rad) of each training set."""
    allp: dict
    """Stage B on all poses, one member per candidate."""
    b: dict
    """Stage B on the training sets, ``T x C`` members (training set major)."""


def _stages(
    cfg: core.Config, ref: Model, q, target, masks, ident, priors, opts: Options, run: dict, n_points: int
) -> _Fits:
    """Stage A (frames only, all poses, then every training set from there) and stage B (every
    candidate on all poses, then on every training set from there: the same optimum, reached
    in a few steps) on the training ``masks (S, K)`` (the last: all poses)."""
    layout = cfg.layout
    S, C = len(masks), len(priors)
    T = S - 1
    fw = np.asarray(masks, float)
    unit = np.repeat(core.weights_of(layout, np.array([core.UNIT_WEIGHTS])), S, 0)
    pa = np.repeat(prior_of(layout, ident, None, frames_only=True)[None], S, 0)
    a_all = core.run_members(
        cfg, core.take(ref, [T]), q, target, fw[[T]], unit[[T]], pa[[T]], **run, label="frames only"
    )
    a_folds = core.run_members(
        cfg,
        core.take(ref, np.arange(T)),
        q,
        target,
        fw[:T],
        unit[:T],
        pa[:T],
        x0=core.relative_x(core.take(ref, np.arange(T)), layout, a_all["model"]),
        **run,
        label="frames only, training sets",
    )
    a = {k: np.concatenate([a_folds[k], a_all[k]]) for k in ("x", "converged", "pos_err", "rot_err")}
    refB = jax.tree.map(lambda u, v: np.concatenate([u, v]), a_folds["model"], a_all["model"])
    sig = core.sigmas_from(a["pos_err"], a["rot_err"], masks, n_points)
    if opts.sigma_pos_mm is not None:
        sig[:, 0] = opts.sigma_pos_mm
    if opts.sigma_rot_rad is not None:
        sig[:, 1] = opts.sigma_rot_rad
    allp = core.run_members(
        cfg,
        core.take(refB, np.full(C, T)),
        q,
        target,
        np.repeat(fw[[T]], C, 0),
        np.repeat(core.weights_of(layout, sig[[T]]), C, 0),
        priors,
        opts.loss_scale,
        **run,
        label="candidates, all poses",
    )
    pick = np.repeat(np.arange(T), C)
    models_b = core.take(refB, pick)
    b = core.run_members(
        cfg,
        models_b,
        q,
        target,
        fw[pick],
        core.weights_of(layout, sig[pick]),
        np.tile(priors, (T, 1)),
        opts.loss_scale,
        x0=core.relative_x(models_b, layout, core.take(allp["model"], np.tile(np.arange(C), T))),
        **run,
        label="cross-validation",
    )
    return _Fits(ref, a, refB, sig, allp, b)


def _outliers_of(cfg: core.Config, fits: _Fits, q, target, masks, dof, priors, opts: Options, run: dict):
    """The outliers of every training set (and of all poses), found with the candidate that fits
    its poses best (the lowest robust noise scale): :func:`._outliers.detect` on those fits."""
    S, K = masks.shape
    T, C = S - 1, len(priors)
    keys = ("x", "norms", "pos_norms", "rot_norms")
    per = {k: np.concatenate([fits.b[k].reshape((T, C) + fits.b[k].shape[1:]), fits.allp[k][None]]) for k in keys}
    poses = cfg.layout.n_points == 0
    sizes = [outliers.standardised({k: v[:, c] for k, v in per.items()}, dof, masks, poses=poses)[1] for c in range(C)]
    size = np.stack([np.sum(np.log(sc[:, : 1 + poses]), -1) for sc in sizes], 1)  # (S, C)
    best = np.argmin(np.where(np.isfinite(size), size, np.inf), 1)
    fit = {k: v[np.arange(S), best] for k, v in per.items()}
    found = dict(poses=poses, sigmas=opts.outlier_sigmas, loss_scale=opts.loss_scale)
    if opts.keep_outliers:
        return outliers.assess(fit, masks, dof, **found)
    weights, prior = core.weights_of(cfg.layout, fits.sig), priors[best]
    refit = lambda w, x0: core.run_members(  # noqa: E731
        cfg, fits.refB, q, target, w, weights, prior, opts.loss_scale, x0=x0, **run, label="outliers"
    )
    return outliers.detect(refit, fit, masks, dof, **found)


def calibrate_data(robot: Robot, data, options: Options | None = None, /, *, progress=None, **kw) -> DataCalibration:
    """Calibrate from measured data with K-fold (and nested) cross-validation.

    **Arguments**: ``data`` a :class:`jaxcal.Measurements` (from :func:`jaxcal.read_measurements`,
    or built from arrays); options as :class:`jaxcal.Options` or keywords, the defaults shared
    with :func:`calibrate`. ``progress(done, total, stage)`` is called as fits complete.

    **Returns** a :class:`DataCalibration` whose ``report`` holds ``train_rms_mm``,
    ``heldout_rms_mm``, ``heldout_max_mm``, ``heldout_median_mm``, ``heldout_rot_rms_deg``
    (nested cross-validation unless ``nested`` is false), ``frames_only_*`` (the same with
    nominal DH and fitted frames), ``choice``, ``cv`` (one row per candidate; its ``failure``
    says which of its fits gave non-finite parameters or did not converge, and why), ``parameters``
    (values, standard errors, units), ``unidentifiable``, ``combinations``,
    ``condition_number``, ``converged``, ``steps``, ``sigma_pos_mm``, ``sigma_rot_deg``,
    ``camera_model``, ``camera_parameters``, ``base``, ``tool``, ``outliers`` and
    ``outlier_detection`` (docs/conventions.md), ``lost_points``, ``dropped_rows`` and, for
    points, ``points``. Training and held-out figures are over the poses not found outliers.
    """
    opts = make_options(options, kw, camera_auto=True)
    q, target, n_points = as_target(robot, data.q, data.measured, batched=False)
    rows_in_file = np.arange(1, len(q) + 1) if getattr(data, "rows", None) is None else np.asarray(data.rows)
    cameras = CAMERA_MODELS if opts.camera == "auto" else (opts.camera,)
    candidates = [
        dataclasses.replace(c, camera=m, name=f"{c.name}, camera {m}" if opts.camera == "auto" else c.name)
        for m in cameras
        for c in parse_params(opts.params, robot, opts.ridge_mm)
    ]
    layout = _layout_for(robot, opts, n_points, cameras)
    if "quadratic" in cameras:
        check_target_in_front(
            target, "quadratic" + (" (tried by camera auto)" if opts.camera == "auto" else ""), rows_in_file
        )
    K, F = len(q), opts.folds
    fid = fold_ids(K, F, opts.seed)
    union = set().union(*(c.dh for c in candidates))
    wanted = list(layout.frames) + list(layout.cameras) + sorted(union)
    needed = core.generic_rank(nominal_model(robot, layout), layout, K, wanted)
    check_enough_poses(K, layout, needed)
    n_train = K - int(np.bincount(fid).max())
    if n_train * layout.rows < needed:
        raise DataError(
            f"too few poses for {F}-fold cross-validation: training sets of {n_train} poses x "
            f"{layout.rows} rows = {n_train * layout.rows} equations for {needed} parameters; use fewer "
            f"folds or more poses",
            option="folds",
        )
    nested = len(candidates) > 1 and K <= opts.nested_max_poses
    outer = np.stack([fid != o for o in range(F)])
    inner, inner_of = [], []
    if nested:
        for o in range(F):
            idx = np.flatnonzero(outer[o])
            sub = fold_ids(len(idx), F, opts.seed + 1 + o)
            for i in range(F):
                msk = np.zeros(K, bool)
                msk[idx[sub != i]] = True
                inner.append(msk)
                inner_of.append(o)
    masks = np.concatenate([outer, np.array(inner, bool).reshape(-1, K), np.ones((1, K), bool)])
    S = len(masks)
    ref = core.start_models(robot.stripped(), layout, q, target, masks, shared=True)
    cfg = core.Config(layout, opts.method, opts.max_steps, opts.rtol, opts.atol, opts.loss, shared_data=True)
    J0, pos0 = core.analyse(core.member(ref, S - 1), layout, q)
    check_units(robot, q, target, n_points, batched=False, model_positions=pos0)
    ident = core.identify(J0, layout)
    C, T = len(candidates), S - 1
    chunk = core.chunk_size(max(T * C, C, S), K, layout, opts.memory_mb)
    run = dict(J0=J0, chunk=chunk, memory_mb=opts.memory_mb, progress=progress)
    priors = np.stack([prior_of(layout, ident, c) for c in candidates])
    fits = _stages(cfg, ref, q, target, masks, ident, priors, opts, run, n_points)

    # outliers: found in every training set (and all poses) on its own, then everything refitted
    # without them; the held-out figures leave out the poses found in all poses
    dof = outliers.position_rows(target)
    det = _outliers_of(cfg, fits, q, target, masks, dof, priors, opts, run)
    if det.flags.any() and not opts.keep_outliers:
        kept = masks & ~det.flags
        fits = _stages(
            cfg,
            core.start_models(robot.stripped(), layout, q, target, kept, shared=True),
            q,
            target,
            kept,
            ident,
            priors,
            opts,
            run,
            n_points,
        )
    left = det.flags if not opts.keep_outliers else np.zeros_like(masks)  # out of every fit
    gone = left[T]  # out of every figure
    a, refB, sig, allp, b = fits.a, fits.refB, fits.sig, fits.allp, fits.b
    ref_all = core.member(fits.ref, T)
    w_all = core.weights_of(layout, sig[[T]])
    pe = b["pos_err"].reshape(T, C, K, -1)
    re = np.degrees(b["rot_err"].reshape(T, C, K))
    held = ~outer
    cv_table, scores = [], []

    def condition(c):  # of candidate c's free parameters, weighted, at the start (all poses)
        Jw = J0 * w_all[0][:, None]
        return core.condition_number(np.einsum("kri,krj->ij", Jw, Jw), list(estimated(priors[c])))

    for c, cand in enumerate(candidates):
        h_pe, t_pe = pe[:F, c][held & ~gone], pe[:F, c][outer & ~left[:F]]
        cv_table.append(
            {
                "name": cand.name,
                "heldout_rms_mm": _rms(h_pe),
                "heldout_max_mm": _max(h_pe),
                "heldout_rot_rms_deg": None if n_points else _rms(re[:F, c][held & ~gone]),
                "train_rms_mm": _rms(t_pe),
                "converged": bool(b["converged"].reshape(T, C)[:F, c].all()),
                "failure": fit_failure(  # its fits on every training set and on all poses
                    np.r_[b["converged"].reshape(T, C)[:, c], allp["converged"][c]],
                    np.isfinite(np.r_[b["x"].reshape(T, C, -1)[:, c], allp["x"][[c]]]).all(-1),
                    np.r_[b["steps"].reshape(T, C)[:, c], allp["steps"][c]],
                    opts.max_steps,
                    lambda i=c: condition(i),
                ),
            }
        )
        scores.append(_rms(h_pe))
    c_final = choose(scores, candidates)
    nested_pe, nested_re = np.zeros(pe.shape[2:]), np.zeros(K)
    nested_choice = []
    for o in range(F):
        if nested:
            rows_o = [F + j for j, oo in enumerate(inner_of) if oo == o]
            ho = ~masks[rows_o] & outer[o] & ~left[o]
            c_o = choose([_rms(pe[rows_o, c][ho]) for c in range(C)], candidates)
        else:
            c_o = c_final
        nested_choice.append(candidates[c_o].name)
        nested_pe[held[o]] = pe[o, c_o][held[o]]
        nested_re[held[o]] = re[o, c_o][held[o]]
    f_pe = np.zeros_like(nested_pe)
    f_re = np.zeros(K)
    for o in range(F):
        f_pe[held[o]] = a["pos_err"][o][held[o]]
        f_re[held[o]] = np.degrees(a["rot_err"][o][held[o]])

    # the final model: all poses, the chosen candidate
    cand = candidates[c_final]
    prior = priors[c_final]
    fin = {k: v[[c_final]] for k, v in allp.items() if k != "model"}
    full = core.wrapped(core.member(allp["model"], c_final), robot)
    x_rel = core.relative_x(ref_all, layout, full)  # DH to the nominal table, frames to the guess
    model = full
    if cand.camera != layout.camera:  # the chosen camera model is a prefix of the largest
        model = Model(
            full.robot, full.points, np.asarray(full.camera_params)[: camera_size(cand.camera)], camera=cand.camera
        )
    st = core.fit_statistics(
        J0,
        w_all[0],
        (~gone).astype(float),
        fin["norms"][0],
        loss=opts.loss,
        loss_scale=opts.loss_scale,
        rows=layout.rows,
        seen=observed(target),
    )
    cov, _ = core.covariance(st["normal"], st["rss"], st["n_rows"], prior)
    active = list(estimated(prior))
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    names, units = layout.names(), layout.units()
    deltas = {names[i]: (float(x_rel[i]), float(se[i]), units[i]) for i in active}
    cam_names = [names[i] for i in layout.cameras[: camera_size(cand.camera)]]
    cond = core.condition_number(st["normal"], active)
    frames_only = core.described(core.member(refB, T), robot).robot
    tr_pe, tr_re = fin["pos_err"][0][~gone], np.degrees(fin["rot_err"][0])[~gone]
    rot = n_points == 0
    train = core.residual_stats(fin["pos_err"][0], fin["rot_err"][0], ~gone, n_points=n_points)
    found = dict(poses=not n_points, sigmas=opts.outlier_sigmas, loss_scale=opts.loss_scale)
    final = outliers.assess(fin, masks[[T]], dof, excluded=None if opts.keep_outliers else gone[None], **found)
    pos_mm = outliers.pose_position_mm(fin["pos_err"][0])
    many = outliers.too_many(final.flags[0], final.sigmas[0], pos_mm, rows_in_file, opts.max_outlier_fraction)
    why = judge(robot, q, target, n_points, layout, opts, train, x_rel, active, many)
    ho_pe, fo_pe = nested_pe[~gone], f_pe[~gone]
    tr_re_all = np.degrees(fin["rot_err"][0])
    rep = {
        "robot": robot.name,
        "data": getattr(data, "source", "arrays"),
        "units": list(getattr(data, "units", ("mm", "rad"))),
        "ignored_columns": list(getattr(data, "ignored", ())),
        "poses": K,
        "position_only": n_points > 0,
        "points": n_points,
        "method": opts.method,
        "folds": F,
        "seed": opts.seed,
        "estimate_base": opts.estimate_base,
        "estimate_tool": opts.estimate_tool,
        "choice": cand.name,
        "choice_rule": "lowest K-fold held-out position RMS; a simpler set within 1% wins",
        "nested": nested,
        "nested_choices": nested_choice,
        "train_rms_mm": _rms(tr_pe),
        "train_max_mm": _max(tr_pe),
        "train_rot_rms_deg": _rms(tr_re) if rot else None,
        "heldout_rms_mm": _rms(ho_pe),
        "heldout_max_mm": _max(ho_pe),
        "heldout_median_mm": _median_pose(ho_pe),
        "heldout_rot_rms_deg": _rms(nested_re[~gone]) if rot else None,
        "frames_only_train_rms_mm": _rms(a["pos_err"][T][~gone]),
        "frames_only_train_max_mm": _max(a["pos_err"][T][~gone]),
        "frames_only_train_rot_rms_deg": _rms(np.degrees(a["rot_err"][T])[~gone]) if rot else None,
        "frames_only_heldout_rms_mm": _rms(fo_pe),
        "frames_only_heldout_max_mm": _max(fo_pe),
        "frames_only_heldout_median_mm": _median_pose(fo_pe),
        "frames_only_heldout_rot_rms_deg": _rms(f_re[~gone]) if rot else None,
        "cv": cv_table,
        "camera_model": cand.camera,
        "camera_model_option": opts.camera,
        "camera_parameters": {k: {"value": deltas[k][0], "std_error": deltas[k][1]} for k in cam_names} or None,
        "sigma_pos_mm": float(sig[T, 0]),
        "sigma_rot_deg": float(np.degrees(sig[T, 1])) if rot else None,
        "parameters": {
            k: {"value": v, "std_error": s, "unit": u} for k, (v, s, u) in deltas.items() if k not in cam_names
        },
        "estimated_dh": [names[i] for i in active if i < layout.n_kin],
        "unidentifiable": [n for n in ident.fixed_names if names.index(n) < layout.n_kin],
        "not_estimated": {n: why for n, why in ident.reasons().items()},
        "combinations": list(ident.combinations),
        "condition_number": cond,
        "converged": bool(fin["converged"][0]),
        "steps": int(fin["steps"][0]),
        "cv_fits_converged": int(np.sum(a["converged"]) + np.sum(b["converged"]) + np.sum(allp["converged"])),
        "cv_fits": int(S + T * C + C),
        "base": frame_doc(model.robot.base),
        "tool": frame_doc(model.robot.tool),
        "plausible": not why,
        "implausible": why or None,
        "notes": list(still_joint_notes(robot, q)),
    }
    rep["outliers"] = outliers.describe(
        final, 0, fin["pos_err"][0], tr_re_all if rot else None, rows_in_file, excluded=not opts.keep_outliers
    )
    rep["outlier_detection"] = {
        "excluded": not opts.keep_outliers,
        "outlier_sigmas": opts.outlier_sigmas,
        "false_alarm_per_pose": outliers.false_alarm(opts.outlier_sigmas),
        "threshold_sigmas": float(outliers.thresholds(layout.rows, opts.outlier_sigmas)),
        "noise_pos_mm": float(final.scale[0, 0] * sig[T, 0]),
        "noise_rot_deg": float(np.degrees(final.scale[0, 1] * sig[T, 1])) if rot else None,
        "max_outlier_fraction": opts.max_outlier_fraction,
        "heldout_rms_mm_all_poses": _rms(nested_pe),  # the flagged poses too: what dropping them hides
    }
    lost = getattr(data, "lost_points", [])  # in the file's rows and point numbers
    rep["lost_points"] = [{"row": r, "point": j} for r, j in lost]
    rep["dropped_rows"] = [int(r) for r in getattr(data, "dropped_rows", ())]
    if n_points:
        rep["points_mm"] = np.asarray(model.points).tolist()
        rep["heldout_points_rms_mm"] = [float(v) for v in np.sqrt(np.nanmean(ho_pe**2, 0))]
    per_pose = {
        "rows": rows_in_file,
        "frames_only_heldout": _squeeze(f_pe),
        "heldout": _squeeze(nested_pe),
        "frames_only_train": _squeeze(a["pos_err"][T]),
        "train": _squeeze(fin["pos_err"][0]),
        "outlier": final.flags[0],
        "sigmas": final.sigmas[0],
        "frames_only_heldout_rot": f_re,
        "heldout_rot": nested_re,
        "frames_only": frames_only,
    }
    return DataCalibration(
        model=core.described(model, robot),
        nominal=robot,
        choice=cand,
        report=rep,
        per_pose=per_pose,
        deltas=deltas,
        covariance=cov,
        layout=layout,
    )


def _squeeze(a):
    a = np.asarray(a)
    return a[..., 0] if a.ndim == 2 and a.shape[-1] == 1 else a
