"""Calibration of real data with honest held-out validation: base/tool initialisation, a
choice of parameter sets and ridge priors by K-fold cross-validation, and the final fit.

## Model
``T(x, q) = exp(xi_b) B0 · A_1(dh + dx_1) ... A_n(dh + dx_n) · X0 exp(xi_t)`` with
``x = [dx (4n), xi_b (6), xi_t (6)]`` (the layout of :func:`jaxcal.error_model.param_names`
with base and tool), ``B0, X0`` from :func:`jaxcal.initial_guess.initial_frames`. Fitted by
:mod:`jaxcal.solvers.manifold` with the analytic identification Jacobian. With a camera
measurement model (``camera``, :mod:`jaxcal.camera`) the modelled pose goes through
``apply_camera(T, c)`` and its unknowns ``c`` are estimated in every candidate (held at 0 in the
frames-only stage); they are not part of the calibrated robot. With ``camera="auto"`` each
parameter set is a candidate once per camera model, so the model is chosen like the set.

The objective, the ridge/pin priors and the noise weighting are in :mod:`jaxcal.cv_fit`.

## Cross-validation
Folds are a seeded permutation of the poses cut into ``K`` nearly equal parts. Each candidate
is fitted on ``K-1`` folds (frames initialised from those poses only) and evaluated on the
held-out fold; the held-out position errors of all folds are pooled into an RMS. The final
candidate is the one with the lowest pooled held-out position RMS (a simpler candidate within
1 % of it wins), refitted on all poses. Because picking the best of several candidates on the
same folds is optimistic, the reported ``heldout_*`` figures come from **nested**
cross-validation: inside each outer training set the candidate is chosen by an inner ``K``-fold
CV, and only then evaluated on the outer held-out fold.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from .camera import CAMERA_MODELS, check_target_in_front, n_params
from .camera import param_names as camera_param_names
from .cv_fit import fit_many, make_setup
from .error_model import pose_error
from .errors import DataError
from .param_sets import Candidate, parse_params
from .robot import Robot
from .uncertainty import frame_doc, standard_errors


# -- errors ------------------------------------------------------------------------------------

def pose_errors(predicted, measured) -> tuple[np.ndarray, np.ndarray]:
    """Per pose: position error norm (mm) and rotation error angle (deg)."""
    e = np.asarray(pose_error(jnp.asarray(measured), jnp.asarray(predicted)))
    return np.linalg.norm(e[..., :3], axis=-1), np.degrees(np.linalg.norm(e[..., 3:], axis=-1))


def _rms(v):
    return float(np.sqrt(np.mean(np.square(v)))) if np.size(v) else float("nan")


def fold_ids(n_poses: int, k: int, seed: int) -> np.ndarray:
    """Fold index (0..k-1) of each pose: a seeded permutation cut into k nearly equal parts."""
    if not 2 <= k <= n_poses:
        raise DataError(f"--folds must be between 2 and the number of poses ({n_poses}), got {k}")
    out = np.empty(n_poses, dtype=np.int64)
    out[np.random.default_rng(seed).permutation(n_poses)] = np.arange(n_poses) % k
    return out


CAMERA_CHOICES = CAMERA_MODELS + ("auto",)
"""Values of ``--camera-model``: a model, or ``auto`` (chosen by cross-validation)."""


# -- the whole procedure -----------------------------------------------------------------------

@dataclasses.dataclass(frozen=True, eq=False)
class DataCalibration:
    """What :func:`calibrate_measurements` returns (lengths mm, angles rad unless named)."""

    robot: Robot
    """The calibrated model, fitted on all poses with the chosen parameter set."""
    nominal: Robot
    choice: Candidate
    """The parameter set chosen by cross-validation (or the one asked for)."""
    report: dict
    """JSON-ready summary (see :func:`calibrate_measurements`)."""
    cv_table: list
    """Per candidate: name, CV held-out position RMS / max (mm), rotation RMS (deg), train RMS."""
    per_pose: dict
    """Per-pose position errors (mm): ``frames_only_heldout``, ``heldout``, ``frames_only_train``,
    ``train``; rotation errors (deg) ``*_rot``; ``rows``: the CSV data rows."""
    deltas: dict
    """name -> (value, standard error) of every estimated parameter (DH errors in mm / rad; base
    and tool twists relative to the all-pose initial guess, mm / rad)."""


def _pooled(pe, re, masks):
    sel = np.asarray(masks, bool)
    out = {"pos_rms_mm": _rms(pe[sel]), "pos_max_mm": float(pe[sel].max()), "rot_rms_deg": _rms(re[sel])}
    return out


def _choose(scores: list[float], candidates) -> int:
    """Lowest score; a simpler candidate (fewer free parameters, stronger prior) within 1 % wins.
    A non-finite score (a fit that failed) never wins; if every score is, that is an error."""
    scores = [s if np.isfinite(s) else np.inf for s in scores]
    best = min(scores)
    if not np.isfinite(best):
        raise DataError(f"every candidate parameter set ({', '.join(c.name for c in candidates)}) failed to fit "
                        f"(non-finite held-out errors); the data or the camera model may be degenerate")
    ok = [i for i, s in enumerate(scores) if s <= 1.01 * best]
    return min(ok, key=lambda i: candidates[i].complexity)


def calibrate_measurements(robot: Robot, q, measured, *, position_only: bool, method: str = "gn",
                           params: str = "auto", ridge_mm: float | None = None, estimate_base: bool = True,
                           estimate_tool: bool = True, folds: int = 5, seed: int = 0,
                           rows=None, camera: str = "none") -> DataCalibration:
    """Calibrate from measured poses with K-fold (and nested) cross-validation.

    **Arguments**: ``q`` ``(K, n)`` rad; ``measured`` ``(K, 4, 4)`` mm; ``params`` see
    :func:`parse_params`; ``folds`` ``K`` of the cross-validation (seeded by ``seed``).

    **Returns** a :class:`DataCalibration` whose ``report`` has ``train_rms_mm``,
    ``heldout_rms_mm``, ``heldout_max_mm``, ``heldout_rot_rms_deg`` (nested CV),
    ``frames_only_*`` (same, nominal DH with base/tool fitted), ``choice``, ``cv``,
    ``parameters`` (deltas with standard errors), ``unidentifiable``, ``condition_number``,
    ``converged``, ``steps``, ``sigma_pos_mm``, ``sigma_rot_deg``, ``camera_model`` (the model of
    the final fit), ``camera_model_option`` (what was asked for, e.g. ``auto``),
    ``camera_parameters``.

    ``camera`` (``none | depth | linear | quadratic``) adds a camera measurement model
    (:mod:`jaxcal.camera`, its unknowns free in every candidate) for camera-on-flange data whose
    target-relative pose comes from PnP: predictions (and so the held-out errors) are of what the
    camera reports. ``camera="auto"`` makes the camera model part of the cross-validated choice:
    every parameter set is tried with each of the four models, so the nested held-out figures
    include that choice.
    """
    if camera not in CAMERA_CHOICES:
        raise DataError(f"--camera-model must be one of {', '.join(CAMERA_CHOICES)}, got {camera!r}")
    if camera != "none" and position_only:
        raise DataError(f"the camera model {camera!r} needs full poses (the camera's axes); the data are "
                        f"position-only")
    models = CAMERA_MODELS if camera == "auto" else (camera,)
    candidates = [dataclasses.replace(c, camera=mdl, name=f"{c.name}, camera {mdl}" if camera == "auto" else c.name)
                  for mdl in models for c in parse_params(params, robot, ridge_mm)]
    q = np.asarray(q, dtype=np.float64)
    measured = np.asarray(measured, dtype=np.float64)
    if "quadratic" in models:
        check_target_in_front(measured, "quadratic" + (" (tried by --camera-model auto)" if camera == "auto" else ""),
                              rows)
    K = len(q)
    setup = make_setup(robot, q, measured, position_only=position_only, candidates=candidates,
                       estimate_base=estimate_base, estimate_tool=estimate_tool, method=method,
                       camera=models[-1])
    fid = fold_ids(K, folds, seed)
    rpp = 3 if position_only else 6
    n_train = K - int(np.bincount(fid).max())
    if n_train * rpp < setup.n_needed:
        raise DataError(f"too few poses for {folds}-fold cross-validation: training sets of {n_train} poses x {rpp} "
                        f"rows = {n_train * rpp} equations for {setup.n_needed} parameters; use fewer folds or "
                        f"more poses")
    outer = np.stack([fid != o for o in range(folds)])
    inner, inner_of = [], []
    if len(candidates) > 1:
        for o in range(folds):
            idx = np.flatnonzero(outer[o])
            if len(idx) < folds:
                raise DataError(f"too few poses ({K}) for nested {folds}-fold cross-validation")
            sub = fold_ids(len(idx), folds, seed + 1 + o)
            for i in range(folds):
                msk = np.zeros(K, bool)
                msk[idx[sub != i]] = True
                inner.append(msk)
                inner_of.append(o)
    masks = np.concatenate([outer, np.array(inner).reshape(-1, K), np.ones((1, K), bool)])
    res = fit_many(setup, masks, candidates)
    meas_b = measured[None]
    # frames only (stage A) and candidates (stage B): errors of every pose under every fit
    fpe, fre = pose_errors(res["frames"]["pred"], meas_b)               # (S, K)
    pe, re = pose_errors(res["pred"], measured[None, None])             # (S, C, K)
    held_outer = ~outer
    scores, cv_table = [], []
    for c, cand in enumerate(candidates):
        st = _pooled(pe[:folds, c], re[:folds, c], held_outer)
        tr = _pooled(pe[:folds, c], re[:folds, c], outer)
        scores.append(st["pos_rms_mm"])
        cv_table.append({"name": cand.name, "heldout_rms_mm": st["pos_rms_mm"], "heldout_max_mm": st["pos_max_mm"],
                         "heldout_rot_rms_deg": st["rot_rms_deg"], "train_rms_mm": tr["pos_rms_mm"],
                         "converged": bool(res["ok"][:folds, c].all())})
    c_final = _choose(scores, candidates)
    # nested: per outer fold, choose on its inner folds, evaluate on the outer held-out fold
    nested_pe, nested_re = np.zeros(K), np.zeros(K)
    nested_choice = []
    for o in range(folds):
        if len(candidates) > 1:
            rows_o = [folds + j for j, oo in enumerate(inner_of) if oo == o]
            ho_o = ~masks[rows_o] & outer[o]
            sc = [_rms(pe[rows_o, c][ho_o]) for c in range(len(candidates))]
            c_o = _choose(sc, candidates)
        else:
            c_o = 0
        nested_choice.append(candidates[c_o].name)
        nested_pe[~outer[o]] = pe[o, c_o, ~outer[o]]
        nested_re[~outer[o]] = re[o, c_o, ~outer[o]]
    f_pe, f_re = np.zeros(K), np.zeros(K)
    for o in range(folds):
        f_pe[~outer[o]] = fpe[o, ~outer[o]]
        f_re[~outer[o]] = fre[o, ~outer[o]]

    # the final model: all poses, chosen candidate
    S = len(masks) - 1
    delta, B, X = res["delta"][S, c_final], res["B"][S, c_final], res["X"][S, c_final]
    cal = robot.replace(dh=np.asarray(robot.dh) + delta, base=B, tool=X, name=f"{robot.name}-calibrated")
    frames_only = robot.replace(base=res["frames"]["B"][S], tool=res["frames"]["X"][S])
    sig = res["sigmas"][S]
    chosen_camera = candidates[c_final].camera
    cam = res["camera"][S, c_final][:n_params(chosen_camera)]
    deltas, cond = standard_errors(setup, cal, candidates[c_final], sig, res["B_init"][S], res["X_init"][S], delta,
                                   cam, chosen_camera)
    cam_names = camera_param_names(chosen_camera)
    names = setup.names
    active_dh = [names[i] for i in setup.free[:setup.n_dh_free] if i in candidates[c_final].dh]
    tr_pe, tr_re = pe[S, c_final], re[S, c_final]
    rep = {
        "robot": robot.name, "poses": K, "position_only": position_only, "method": method, "folds": folds,
        "seed": seed, "estimate_base": estimate_base, "estimate_tool": estimate_tool,
        "choice": candidates[c_final].name, "choice_rule": "lowest K-fold held-out position RMS; a simpler set "
        "within 1% wins", "nested_choices": nested_choice,
        "train_rms_mm": _rms(tr_pe), "train_max_mm": float(tr_pe.max()),
        "train_rot_rms_deg": None if position_only else _rms(tr_re),
        "heldout_rms_mm": _rms(nested_pe), "heldout_max_mm": float(nested_pe.max()),
        "heldout_median_mm": float(np.median(nested_pe)),
        "heldout_rot_rms_deg": None if position_only else _rms(nested_re),
        "frames_only_train_rms_mm": _rms(fpe[S]), "frames_only_train_max_mm": float(fpe[S].max()),
        "frames_only_train_rot_rms_deg": None if position_only else _rms(fre[S]),
        "frames_only_heldout_rms_mm": _rms(f_pe), "frames_only_heldout_max_mm": float(f_pe.max()),
        "frames_only_heldout_median_mm": float(np.median(f_pe)),
        "frames_only_heldout_rot_rms_deg": None if position_only else _rms(f_re),
        "cv": cv_table,
        "camera_model": chosen_camera, "camera_model_option": camera,
        "camera_parameters": {k: {"value": deltas[k][0], "std_error": deltas[k][1]} for k in cam_names} or None,
        "sigma_pos_mm": float(sig[0]), "sigma_rot_deg": None if position_only else float(np.degrees(sig[1])),
        "parameters": {k: {"value": v, "std_error": s, "unit": u} for k, (v, s, u) in deltas.items()
                       if k not in cam_names},
        "estimated_dh": active_dh,
        "unidentifiable": list(setup.ident.fixed_names),
        "combinations": list(setup.ident.combinations),
        "condition_number": cond,
        "converged": bool(res["ok"][S, c_final]), "steps": int(res["steps"][S, c_final]),
        "cv_fits_converged": int(res["ok"].sum() + res["frames"]["ok"].sum()),
        "cv_fits": int(res["ok"].size + res["frames"]["ok"].size),
        "base": frame_doc(B), "tool": frame_doc(X),
    }
    rows = np.arange(1, K + 1) if rows is None else np.asarray(rows)
    per_pose = {"rows": rows, "frames_only_heldout": f_pe, "heldout": nested_pe, "frames_only_train": fpe[S],
                "train": tr_pe, "frames_only_heldout_rot": f_re, "heldout_rot": nested_re,
                "frames_only": frames_only}
    return DataCalibration(robot=cal, nominal=robot, choice=candidates[c_final], report=rep, cv_table=cv_table,
                           per_pose=per_pose, deltas=deltas)
