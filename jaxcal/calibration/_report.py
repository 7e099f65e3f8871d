"""The result of :func:`jaxcal.calibrate_data`: the final model, its standard errors, the held-out
figures of the nested fits, and the JSON report (its fields: docs/conventions.md)."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import numpy as np

from .._io import json_text
from ..camera import n_params as camera_size
from ..kinematics import fk
from ..model import Layout, Model, measured_robot, observed, predict
from ..robot import Robot
from ..solvers import robust_scale
from . import _core as core
from . import _outliers as outliers
from . import _plausibility as plausibility
from . import _selection as selection
from ._checks import joint_ranges, limit_notes, unwrapped
from ._evaluate import rigid_figures
from ._markers import drift, moved_point
from ._param_sets import Candidate
from ._single import estimated, judge, narrow_joint_notes, still_joint_notes

RULE = (
    f"lowest score, the RMS of the K-fold and range-end held-out errors (linearised); the simplest set within "
    f"one standard error of it (at least {100 * selection.SIMPLER_TOLERANCE:g} %) wins; then its parameters "
    f"pruned, least significant first, as far as held-out folds that order the parameters on their own "
    f"training poses support: the sparsest "
    + (f"within {selection.PRUNE_SE:g} standard error(s) and " if selection.PRUNE_SE else "whose score is within ")
    + f"{100 * selection.PRUNE_TOLERANCE:g} % of the best"
)


@dataclasses.dataclass(frozen=True, eq=False)
class DataCalibration:
    """What :func:`calibrate_data` returns (lengths mm, angles rad unless named)."""

    model: Model
    """The calibrated model, fitted on all poses with the chosen parameters."""
    nominal: Robot
    choice: Candidate
    report: dict
    """JSON-ready: everything ``jaxcal calibrate --json`` writes (see :func:`calibrate_data`)."""
    per_pose: dict
    """Per pose: ``rows`` (data rows), position errors (mm) ``heldout``, ``train``,
    ``frames_only_heldout``, ``frames_only_train`` (``(K, M)`` for several points), rotation
    errors (deg) ``*_rot``; ``outlier``, ``sigmas``; ``scored``: the poses the held-out figures
    are over; ``frames_only``: the frames-only robot."""
    deltas: dict
    """name -> (value, standard error, unit) of every estimated parameter (DH errors relative to
    the nominal table; frame twists relative to the closed-form guess)."""
    covariance: np.ndarray | None = None
    """``(m, m)`` covariance of the final fit's parameters, named by ``layout.names()`` (mm, rad;
    0 where a parameter is held), whose diagonal gives the standard errors of :attr:`deltas`."""
    layout: Layout | None = None
    """The parameters of :attr:`covariance` (the largest camera model tried)."""
    training_ranges: dict | None = None
    """Joint name -> ``(lowest, highest)`` (mm, rad) of the poses the model was fitted on, which
    the written model files record (:func:`jaxcal.robot.read_training_ranges`)."""

    @property
    def robot(self) -> Robot:
        return measured_robot(self.model)

    @property
    def cv_table(self) -> list:
        return self.report["cv"]

    def to_json(self) -> str:
        return json_text(self.report)


def _noise(pos_err, flags, sigma_mm: float, leverage) -> float:
    """The final fit's position noise per coordinate (mm): :func:`jaxcal.solvers.robust_scale` of
    its position errors (three coordinates each) on the poses fitted, in units of the weight
    ``sigma_mm`` as the detector's. Neither outliers nor a given loss scale move it, unlike
    ``sigma_pos_mm`` (the fits' weight: the frames-only residual, the robot's own errors too).
    A fit absorbs part of the noise in its parameters, so the residuals' scale is divided by
    ``sqrt(1 - mean leverage)`` of those rows (the effective parameter count under the prior)."""
    e = np.asarray(pos_err, float)
    K, M = e.shape
    h = np.asarray(leverage).reshape(K, -1, 3)[:, :M].sum(-1)  # (K, M): a point's three rows
    use = ~np.asarray(flags, bool)[:, None] & np.isfinite(e)
    if not use.any():
        return float("nan")
    scale = float(robust_scale(e[use] / sigma_mm, 3)) * sigma_mm
    return scale / np.sqrt(max(1.0 - h[use].sum() / (3.0 * use.sum()), 1e-3))


def _rms(v) -> float:
    """RMS of all the finite values (a lost point is NaN)."""
    return float(core.nan_rms(v, None))


def _max(v) -> float:
    v = np.asarray(v)
    v = v[np.isfinite(v)]
    return float(v.max()) if v.size else float("nan")


def _median_pose(pe) -> float:
    """Median over poses of each pose's RMS over its points (``pe (K, M)``, NaN: lost)."""
    pe = np.asarray(pe)
    return float(np.median(np.sqrt(np.nanmean(pe**2, -1)))) if len(pe) else float("nan")


def _squeeze(a):
    a = np.asarray(a)
    return a[..., 0] if a.ndim == 2 and a.shape[-1] == 1 else a


def frame_doc(T) -> dict:
    """A frame as ``xyz_mm`` and roll-pitch-yaw ``rpy_deg`` (fixed axes x-y-z; at pitch ±90 deg,
    the robot files' convention of :func:`jaxcal.lie.matrix_to_rpy`, without a warning)."""
    from ..lie import matrix_to_rpy

    T = np.asarray(T)
    return {
        "xyz_mm": [float(v) for v in T[:3, 3]],
        "rpy_deg": [float(v) for v in np.degrees(np.asarray(matrix_to_rpy(T[:3, :3])))],
    }


def training_ranges(robot, q, valid, *, file_units: bool = False) -> dict:
    """``{joint name: [lowest, highest]}`` of the poses a model was fitted on: mm and rad, or in the
    robot file's units (a prismatic joint in its length unit)."""
    lo, hi = joint_ranges(robot, np.asarray(q)[np.asarray(valid, bool)])
    scale = robot.joint_scale() if file_units else np.ones(len(lo))
    return {name: [float(lo[j] / scale[j]), float(hi[j] / scale[j])] for j, name in enumerate(robot.joint_names)}


def _heldout(fits, fr, p, scored):
    """Held-out position errors (mm) of the nested fits and of the frames-only fits: ``(K, M)`` on
    the K-fold sets (each pose held out once), and the range-end sets' errors pooled over the
    poses ``scored``."""
    O, F = len(p.held), p.n_kfold
    pe, fo = np.asarray(fits["pos_err"]), np.asarray(fr.fit["pos_err"])
    re, fre = np.degrees(np.asarray(fits["rot_err"])), np.degrees(np.asarray(fr.fit["rot_err"]))
    out = {k: np.full(pe.shape[1:], np.nan) for k in ("pe", "fo")} | {
        k: np.full(len(p.q), np.nan) for k in ("re", "fre")
    }
    for o in range(F):
        h = p.held[o]
        out["pe"][h], out["fo"][h], out["re"][h], out["fre"][h] = pe[o][h], fo[o][h], re[o][h], fre[o][h]
    ends = [p.held[o] & scored for o in range(F, O)]
    out["ends"] = np.concatenate([pe[F + i][h] for i, h in enumerate(ends)]) if ends else np.zeros((0,) + pe.shape[2:])
    out["fo_ends"] = np.concatenate([fo[F + i][h] for i, h in enumerate(ends)]) if ends else out["ends"]
    return out


ODD_POINT = 3.0
"""A measured point whose held-out error is more than this many times the median of the other
points' is named in the report's notes. Points farther from the flange err more by their lever
alone, by well under this; a marker that slipped on the tool or one much noisier than the rest
errs several times more, and one noise weight for all points hides it."""


FEW_SIGHTINGS = 10
"""A point seen in fewer rows than this is not blamed for its held-out error: its place on the
tool rests on those few rows, and each fold that holds some out leaves it barely determined."""


def _odd_point(p, pe) -> str:
    """A note naming the point whose held-out error ``pe (K, M)`` stands far above the other
    points' (:data:`ODD_POINT`; three points or more), or ``""``."""
    if p.n_points < 3:
        return ""
    v = core.nan_rms(pe[p.valid], 0)
    if not np.isfinite(v).sum() > 1:
        return ""
    j = int(np.nanargmax(v))
    m = float(np.nanmedian(np.delete(v, j)))
    if not (v[j] > ODD_POINT * m and v[j] > 1e-3):  # 1 um: below any tracker's noise (noise-free data)
        return ""
    nums = list(getattr(p.data, "point_numbers", ()) or range(1, p.n_points + 1))
    keep = ",".join(str(n) for k, n in enumerate(nums) if k != j)
    seen = int(np.isfinite(pe[p.valid][:, j]).sum())
    if seen < FEW_SIGHTINGS:  # its place on the tool rests on these rows, each held out leaves fewer
        return (
            f"point {nums[j]} is seen in only {seen} rows: its place on the tool rests on them, and held out it "
            f"errs {v[j]:.3g} mm RMS, {v[j] / m:.1f} times the other points' median ({m:.3g} mm). Measure it in "
            f"more poses, or calibrate without it (--points {keep})"
        )
    return (
        f"point {nums[j]} errs {v[j]:.3g} mm RMS on held-out poses, {v[j] / m:.1f} times the other points' "
        f"median ({m:.3g} mm): a marker that moved on the tool during the session, or a noisy or mislabelled "
        f"one? Calibrate without it (--points {keep}) and compare the held-out figures"
    )


def _drift_doc(p, model: Model) -> dict | None:
    """The measurements' drift along the file's rows (:func:`._markers.drift`) as JSON, or None."""
    target = np.asarray(p.target)
    pred = np.asarray(predict(model, p.q))
    res = (target - pred)[:, None, :3, 3] if target.shape[-2:] == (4, 4) else target - pred
    d = drift(p.rows, res, p.valid)
    if d is None:
        return None
    size = float(np.linalg.norm(d.change))
    return {
        "kind": "linear" if d.step is None else "step",
        "mm": size,
        "direction": (d.change / size).tolist(),
        "sigmas": float(d.sigmas),
        "noise_mm": d.noise,
        "from_row": int(d.rows[0] if d.step is None else d.rows[d.step - 1]),
        "to_row": int(d.rows[-1] if d.step is None else d.rows[d.step]),
    }


def _drift_note(d: dict) -> str:
    """What the report says of measurements that drift along the file, or jump."""
    x, y, z = d["direction"]
    along = f"along ({x:.2f}, {y:.2f}, {z:.2f}) in the measurement frame"
    if d["kind"] == "step":
        return (
            f"the measurements jump between rows {d['from_row']} and {d['to_row']}: the residual steps by "
            f"{d['mm']:.3g} mm there, {along} (a step {d['sigmas']:.0f} standard errors from none): the tracker "
            "or the base moved then? One base frame averages it. Calibrate the rows before and after apart"
        )
    return (
        f"the measurements drift along the file: the residual moves by {d['mm']:.3g} mm from row {d['from_row']} to "
        f"row {d['to_row']}, {along} (a trend {d['sigmas']:.0f} standard errors from none): the tracker, the base or "
        "the arm's temperature changing during the session, or postures that change steadily along the file where "
        "the model misses something. One base frame averages it. Measure a reference posture at the start and the "
        "end, or calibrate parts of the session apart"
    )


def _moved_note(p, model: Model, noise_mm: float) -> str:
    """A note naming the point that moved on the tool partway through the data (:mod:`._markers`),
    or ``""``."""
    if p.n_points < 2:
        return ""
    R = np.asarray(fk(model.robot, p.q))[:, :3, :3]
    found = moved_point(R, np.asarray(p.target) - np.asarray(predict(model, p.q)), np.asarray(p.valid), noise_mm)
    if found is None:
        return ""
    j, last, first, step, sigmas = found
    nums = list(getattr(p.data, "point_numbers", ()) or range(1, p.n_points + 1))
    where = (
        f"between rows {p.rows[last]} and {p.rows[first]}: its error steps there by {np.linalg.norm(step):.3g} mm in "
        f"the tool's frame ({sigmas:.0f} standard deviations of the noise)"
    )
    if j < 0:  # two points: each one's error against the other's, which moved is not told
        return (
            f"point {nums[0]} or point {nums[1]} seems to have moved on the tool {where}, one against the other; one "
            "position for each fits neither part. Calibrate the rows before and after apart"
        )
    keep = ",".join(str(n) for i, n in enumerate(nums) if i != j)
    return (
        f"point {nums[j]} seems to have moved on the tool {where}, the other points' not; one position for it "
        f"fits neither part. Calibrate the rows before and after apart, or without it (--points {keep})"
    )


def _unfitted_points(p) -> tuple[str, str]:
    """``(finding, cause)`` for measured points seen, but for one pose at most, only at poses left
    out as outliers (a ghost marker, a reflection fixed in the room): their place on the tool is
    estimated from no pose or fitted exactly by one, checked by none, yet a model would carry
    them; ``("", "")`` when every point is seen at two poses fitted or not at outliers."""
    if not p.n_points:
        return "", ""
    seen = np.isfinite(np.asarray(p.target)).all(-1)  # (K, M)
    fitted, out = seen[p.valid].sum(0), seen[~p.valid].sum(0)
    gone = [j for j in range(p.n_points) if fitted[j] <= 1 and out[j] > 0]
    if not gone:
        return "", ""
    nums = list(getattr(p.data, "point_numbers", ()) or range(1, p.n_points + 1))

    def rows(mask):
        r = p.rows[mask]
        return ", ".join(str(int(v)) for v in r[:10]) + (", ..." if len(r) > 10 else "")

    finding = "; ".join(
        f"point {nums[j]} is measured only at rows left out as outliers ({rows(seen[:, j] & ~p.valid)})"
        + (
            f" and at one pose fitted (row {rows(seen[:, j] & p.valid)}): its place on the tool rests on that one "
            "reading, checked by none"
            if fitted[j]
            else ": its place on the tool is not estimated"
        )
        for j in gone
    )
    keep = ",".join(str(n) for i, n in enumerate(nums) if i not in gone)
    return finding, (
        "a marker that is not on the tool (a reflection, a ghost, another object's)? Calibrate without it "
        f"(--points {keep})"
    )


def _why_not(p, final, names) -> dict:
    """Why each parameter of the layout is not estimated (identifiability, the chosen set, or
    pruned by the selection)."""
    out = dict(p.ident.reasons())
    cand, ch = final.candidate, final.choice
    pruned = {j: (t, s) for j, t, s in ch.pruned}
    for i in np.flatnonzero((final.free[ch.index]) & ~ch.free):
        t, s = pruned.get(int(i), (np.nan, np.nan))
        out[names[i]] = (
            f"dropped by the selection: its estimate was {t:.2g} standard errors from 0, and with as many "
            f"dropped as up to it (each held-out fold its own) the score was {s:.4g} mm (the set's "
            f"{ch.scores[ch.index]:.4g} mm)"
        )
    for i in np.flatnonzero(~final.free[ch.index] & (final.prior >= core.PIN)):
        if names[i] not in out and (i < p.layout.n_kin or i in p.layout.compliances):
            out[names[i]] = f"not in the chosen set ({cand.name})"
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class _Final:
    """The final fit (all poses, the chosen model) and its statistics."""

    model: Model
    """With the chosen camera model's unknowns only."""
    fit: dict
    """The fit's arrays (:func:`._core.run_members`, one member)."""
    x: np.ndarray
    """Parameters relative to the nominal kinematics and the frames' closed-form guess."""
    deltas: dict
    cov: np.ndarray
    normal: np.ndarray
    active: list
    cam_names: list
    leverage: np.ndarray
    """``(K, rows)``: each residual row's leverage (:func:`._core.leverage`)."""


def _final(p, fr, final, fits) -> _Final:
    """The final model (the last member of the nested fits), its standard errors and covariance."""
    layout, O = p.layout, len(p.held)
    cand = final.candidate
    fin = {k: np.asarray(v)[[O]] for k, v in fits.items() if k != "model"}
    full = core.wrapped(core.member(fits["model"], O), p.robot)
    x = core.relative_x(core.member(fr.start, -1), layout, full)
    model = full
    if cand.camera != layout.camera:  # the chosen camera model is a prefix of the largest
        cam = np.asarray(full.camera_params)[: camera_size(cand.camera)]
        model = Model(full.robot, full.points, cam, camera=cand.camera)
    comp = model.robot.compliance
    if comp is not None and p.robot.compliance is None and not np.any(np.asarray(comp) != 0):
        # every compliance held at zero: a rigid arm, and its files say so (no zero per joint)
        rigid = eqx.tree_at(lambda r: r.compliance, model.robot, None, is_leaf=lambda v: v is None)
        model = Model(rigid, model.points, model.camera_params, camera=model.camera)
    w = core.weights_of(layout, fr.sig[[-1]])[0]
    J_fin = core.analyse(core.member(fits["model"], O), layout, p.q)[0]
    st = core.fit_statistics(
        J_fin, w, p.valid.astype(float), fin["norms"][0], loss=p.opts.loss, loss_scale=p.opts.loss_scale,
        rows=layout.rows, seen=observed(p.target),
    )  # fmt: skip
    cov, _ = core.covariance(st["normal"], st["rss"], st["n_rows"], final.prior)
    lev = core.leverage(J_fin, w, st, final.prior, observed(p.target))
    active = list(estimated(final.prior))
    model, x, cov, moved = core.centred(model, layout, p.q, p.valid, x, cov, active)
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    names, units = layout.names(), layout.units()
    deltas = {names[i]: (float(x[i]), float(se[i]), units[i]) for i in sorted(set(active) | set(moved))}
    cam_names = [names[i] for i in layout.cameras[: camera_size(cand.camera)]]
    return _Final(model, fin, x, deltas, cov, st["normal"], active, cam_names, lev)


def _figures(p, fr, fits, fin: dict, h: dict, scored) -> dict:
    """Training figures over the poses fitted; held-out (new postures, beyond the ranges) and
    frames-only figures (mm, deg) over the poses ``scored``."""
    rot, kept = p.n_points == 0, p.valid
    ho, fo = h["pe"][scored], h["fo"][scored]
    tr_pe, tr_re = fin["pos_err"][0][kept], np.degrees(fin["rot_err"][0])[kept]
    a_pe, a_re = np.asarray(fr.fit["pos_err"])[-1][kept], np.degrees(np.asarray(fr.fit["rot_err"])[-1])[kept]
    return {
        "train_rms_mm": _rms(tr_pe),
        "train_max_mm": _max(tr_pe),
        "train_rot_rms_deg": _rms(tr_re) if rot else None,
        "heldout_rms_mm": _rms(ho),
        "heldout_max_mm": _max(ho),
        "heldout_median_mm": _median_pose(ho),
        "heldout_rot_rms_deg": _rms(h["re"][scored]) if rot else None,
        "extrapolation_rms_mm": _rms(h["ends"]),
        "extrapolation_max_mm": _max(h["ends"]),
        "expected_error_mm": {"new_postures": _rms(ho), "beyond_training_ranges": _rms(h["ends"])},
        "frames_only_train_rms_mm": _rms(a_pe),
        "frames_only_train_max_mm": _max(a_pe),
        "frames_only_train_rot_rms_deg": _rms(a_re) if rot else None,
        "frames_only_heldout_rms_mm": _rms(fo),
        "frames_only_heldout_max_mm": _max(fo),
        "frames_only_heldout_median_mm": _median_pose(fo),
        "frames_only_heldout_rot_rms_deg": _rms(h["fre"][scored]) if rot else None,
        "frames_only_extrapolation_rms_mm": _rms(h["fo_ends"]),
        "cv_fits_converged": int(np.sum(fits["converged"][: len(p.held)]) + np.sum(fr.fit["converged"])),
        "cv_fits": int(len(p.held) + len(fr.sig)),
        "lm_refits": int(np.sum(fits["retried"]) + np.sum(fr.fit["retried"])),
    }


def _choice(p, final, per_fold, names) -> dict:
    """What was chosen and why: the candidates' scores, the parameters kept and dropped."""
    ch, cand, layout = final.choice, final.candidate, p.layout
    kfold, ends = ch.parts
    return {
        "choice": cand.name,
        "choice_rule": (
            RULE
            if p.auto
            else "lowest score, the RMS of the K-fold and range-end held-out errors (linearised), among the "
            f"candidates of params {p.opts.params!r} (compliance, camera models); nothing pruned"
            if len(p.candidates) > 1
            else f"given (params {p.opts.params!r}): nothing chosen or pruned"
        ),
        "nested": p.nested,
        "nested_choices": [f"{s.candidate.name} ({int(s.choice.free.sum())} free)" for s in per_fold[: p.n_kfold]],
        "cv": [
            {
                "name": c.name,
                "score_mm": float(ch.scores[i]),
                "heldout_rms_mm": float(kfold[i]),
                "extrapolation_rms_mm": float(ends[i]),
                "free_parameters": int(final.free[i].sum()),
                "failure": None if np.isfinite(ch.scores[i]) else selection.failure(ch.conditions[i]),
            }
            for i, c in enumerate(p.candidates)
        ],
        "selection": {
            "candidate": cand.name,
            "score_mm": float(ch.scores[ch.index]),
            "pruned_score_mm": float(ch.score),
            "kept": [names[i] for i in np.flatnonzero(ch.free) if i < layout.n_kin or i in layout.compliances],
            "dropped": [{"parameter": names[j], "t": float(t), "score_mm": float(s)} for j, t, s in ch.pruned],
        },
        # whether the model estimates a compliance: a candidate with them may have pruned them all
        "compliance": bool(np.any(ch.free[list(layout.compliances)])) if layout.n_comp and cand.compliance else False,
        "ridge_mm": cand.ridge_mm,
        "not_estimated": _why_not(p, final, names),
    }


def _region_doc(p, reg, without: float) -> dict | None:
    """JSON of a :class:`._outliers.Region` in the robot file's units, or ``None``; ``without``: the
    held-out RMS (mm) over the poses fitted alone, the figure that scattered gross errors would get."""
    if reg is None:
        return None
    j, scale = reg.joint, float(p.robot.joint_scale()[reg.joint])
    return {
        "joint": p.robot.joint_names[j],
        "end": reg.end,
        "bound": reg.bound / scale,
        "centre": reg.centre / scale if reg.end == "both" else None,
        "unit": p.robot.units[1] if p.robot.joint_types[j] == "R" else p.robot.units[0],
        "rows": [int(r) for r in p.rows[reg.flags]],
        "poses_in_region": reg.poses,
        "chance": reg.chance,
        "heldout_rms_mm_without_them": without,
    }


def _joint_label(p, doc: dict) -> str:
    """``joint 2 (q2)``: the joint of a region's JSON, by its number in the chain and its name."""
    return f"joint {p.robot.joint_names.index(doc['joint']) + 1} ({doc['joint']})"


def _region_note(p, doc: dict, kept: bool) -> str:
    """What the report says of outliers that lie together in one part of a joint's range."""
    b, u, name = doc["bound"], doc["unit"], _joint_label(p, doc)
    if doc["end"] == "both":
        lo, hi = doc["centre"] - b, doc["centre"] + b
        where = f"at both ends of the range of {name}, {lo:.4g} {u} and below or {hi:.4g} {u} and above"
    else:
        side = "above" if doc["end"] == "high" else "below"
        where = f"at the {doc['end']} end of the range of {name}, {b:.4g} {u} and {side}"
    rows, n = doc["rows"], len(doc["rows"])
    listed = ", ".join(map(str, rows[:8])) + (f" and {n - 8} more" if n > 8 else "")
    how = (
        "they are fitted (--keep-outliers)"
        if kept
        else "they stay out of the fit, but the held-out figures count them: there, the model errs as they "
        "say, and leaving them out of the figures would hide it (held-out RMS without them "
        f"{doc['heldout_rms_mm_without_them']:.3g} mm). Check that part of the range; --keep-outliers fits "
        "them; if their measurements are faulty, remove the rows"
    )
    return (
        f"outliers together: rows {listed} ({n} of the {doc['poses_in_region']} poses there) lie {where}, "
        f"where scattered gross errors would fall with probability {doc['chance']:.1g}: more likely the arm's "
        "own error in that part of its range (a sag, a cable, a joint stop) or a measurement fault there "
        f"(the tracker's line of sight) than bad rows; {how}"
    )


def _hint_note(p, doc: dict, detection: dict) -> str:
    """What the report says of a few outliers together at an end of a joint's range."""
    name = _joint_label(p, doc)
    where = "both ends" if doc["end"] == "both" else f"the {doc['end']} end"
    rows, m = doc["rows"], doc["poses_in_region"]
    among = "are the poses" if m == len(rows) else f"lie among the {m} poses"
    return (
        f"rows {', '.join(map(str, rows))}, left out as outliers, {among} farthest out at {where} of the range of "
        f"{name} (probability {doc['chance']:.1g} for scattered errors; too few to be counted as a region): if that "
        "is the arm's own error there, not bad measurements, the held-out figures leave it out; with the outliers "
        f"scored the held-out RMS is {detection['heldout_rms_mm_all_poses']:.3g} mm (--keep-outliers fits them)"
    )


def _outlier_section(p, fr, det, last, fin: dict, h: dict, reg, faults) -> dict:
    """The outliers found and how (docs/conventions.md#outliers); ``reg`` where they lie together,
    ``faults`` the poses whose points do not move as one rigid body."""
    opts, rot = p.opts, p.n_points == 0
    return {
        "outliers": outliers.describe(
            last,
            0,
            fin["pos_err"][0],
            np.degrees(fin["rot_err"][0]) if rot else None,
            p.rows,
            excluded=not opts.keep_outliers,
            point_numbers=getattr(p.data, "point_numbers", ()),
        ),  # fmt: skip
        "outlier_detection": {
            "excluded": not opts.keep_outliers,
            "outlier_sigmas": opts.outlier_sigmas,
            "false_alarm_per_pose": outliers.false_alarm(opts.outlier_sigmas),
            "threshold_sigmas": float(outliers.thresholds(p.layout.rows, opts.outlier_sigmas)),
            # the noise of the final model's residual, in which the listed sigmas are measured
            "noise_pos_mm": float(last.scale[0, 0] * fr.sig[-1, 0]),
            "noise_rot_deg": float(np.degrees(last.scale[0, 1] * fr.sig[-1, 1])) if rot else None,
            "max_outlier_fraction": opts.max_outlier_fraction,
            "heldout_rms_mm_all_poses": _rms(h["pe"]),  # the flagged poses too: what leaving them out hides
            "heldout_rot_rms_deg_all_poses": _rms(h["re"]) if rot else None,
            # flagged by the detection, then predicted by the calibrated model (the second look)
            "taken_back_rows": [int(r) for r in p.rows[det.flags[0] & p.valid]] if not opts.keep_outliers else [],
            # outliers together in one part of a joint's range: scored in the held-out figures
            "region": _region_doc(p, reg, _rms(h["pe"][p.valid & ~(reg.flags if reg is not None else False)])),
            "not_rigid_rows": [int(r) for r in p.rows[faults]],
        },
        "lost_points": [{"row": r, "point": j} for r, j in getattr(p.data, "lost_points", [])],
        "dropped_rows": [int(r) for r in getattr(p.data, "dropped_rows", ())],
    }


def _limits_doc(limits) -> dict:
    """The resolved plausibility limits under their options' names and units."""
    return {
        "max_residual_mm": float(limits.residual_mm),
        "max_rotation_deg": float(limits.rotation_deg),
        "max_length_change_mm": float(limits.length_mm),
        "max_angle_change_deg": float(np.degrees(limits.angle_rad)),
        "max_camera_change": float(limits.camera),
    }


def report_of(p, fr, det, lin, final, per_fold, fits, named=None) -> DataCalibration:
    """The :class:`DataCalibration` of a run of :func:`jaxcal.calibrate_data` from its stages.
    ``named``: the poses to name as outliers (``keep_outliers``: those a run without the option
    leaves out), judged in the final fit; else those the final fit's rule flags."""
    opts, layout, robot, q = p.opts, p.layout, p.robot, p.q
    f = _final(p, fr, final, fits)
    fin, names = f.fit, layout.names()
    train = core.residual_stats(fin["pos_err"][0], fin["rot_err"][0], p.valid, n_points=p.n_points)
    last = outliers.judged(fin, p.target, p.n_points, opts, None if opts.keep_outliers else ~p.valid[None])
    if named is not None:
        last = dataclasses.replace(last, flags=np.asarray(named, bool)[None])
    pos_mm = outliers.pose_position_mm(fin["pos_err"][0])
    rot_deg = np.degrees(np.asarray(fin["rot_err"][0])) if p.n_points == 0 else None
    many = outliers.too_many(
        last.flags[0], last.sigmas[0], pos_mm, p.rows, opts.max_outlier_fraction, rotation_deg=rot_deg
    )
    swap = ""
    # the points the model predicts, where flagged poses of several points are looked at
    pred = predict(f.model, q) if p.n_points > 1 and last.flags[0].any() else None
    if many:
        many += outliers.zeros_note(p.target, p.n_points, last.flags[0], getattr(p.data, "point_numbers", ()))
        if p.n_points > 1:
            noise = float(last.scale[0, 0] * fr.sig[-1, 0])
            swap = outliers.swaps_note(
                pred, p.target, last.flags[0], noise, p.rows, getattr(p.data, "point_numbers", ())
            )
            if not swap:  # one marker off in them all (slipped): named, with the points that leave it out
                many += outliers.one_point_note(
                    fin["pos_err"][0], last.flags[0], p.rows, getattr(p.data, "point_numbers", ())
                )
    se = np.array([f.deltas[n][1] if n in f.deltas else 0.0 for n in names])
    noise = _noise(fin["pos_err"][0], last.flags[0], float(fr.sig[-1, 0]), f.leverage)
    # a point that moved on the tool partway: one position fits neither part, and the arm's
    # parameters take up the rest; a measurement fault, refused with its rows and the points to keep
    moved = _moved_note(p, f.model, noise)
    unfitted, ghost = _unfitted_points(p)
    extra = "; ".join(
        filter(None, (many, "a measured point moved on the tool during the session" if moved else "", unfitted))
    )
    why = judge(
        robot, q, p.target, p.n_points, layout, opts, train, f.x, f.active, extra, se=se, cause=swap or moved or ghost
    )
    if why and opts.keep_outliers and last.flags[0].any():  # said beside the diagnosis, which may name another cause
        rows_kept = p.rows[last.flags[0]]
        listed = ", ".join(str(int(r)) for r in rows_kept[:10]) + (", ..." if len(rows_kept) > 10 else "")
        why += (
            f"; the fit keeps the outliers it names (--keep-outliers, keep_outliers): row(s) {listed}"
            + outliers.zeros_note(p.target, p.n_points, last.flags[0], getattr(p.data, "point_numbers", ()))
            + "; without the option they are left out"
        )
    qu = unwrapped(robot, q)  # a continuous joint on the arc it visited
    # a pose whose points do not move together is a measurement fault, whatever joint range it is in
    faults = np.zeros(len(q), bool)
    if p.n_points >= 3 and pred is not None:
        faults = outliers.not_rigid(pred, p.target, last.flags[0], opts.outlier_sigmas)
    arm = last.flags[0] & ~faults
    reg = outliers.region(qu, arm)
    hint = None
    if reg is None and not opts.keep_outliers:  # too few to make a region, but together at an end
        hint = outliers.region(qu, arm, chance=outliers.HINT_CHANCE, least=2)
    scored = p.valid | (reg.flags if reg is not None else False)
    h = _heldout(fits, fr, p, scored)
    rep = {
        "robot": robot.name,
        "data": getattr(p.data, "source", "arrays"),
        "units": list(getattr(p.data, "units", ("mm", "rad"))),
        "ignored_columns": list(getattr(p.data, "ignored", ())),
        "poses": len(q),
        "position_only": p.n_points > 0,
        "points": p.n_points,
        "point_numbers": list(getattr(p.data, "numbers", range(1, p.n_points + 1))),
        "method": opts.method,
        "folds": opts.folds,
        "range_end_folds": len(p.held) - p.n_kfold,
        "seed": opts.seed,
        "estimate_base": opts.estimate_base,
        "estimate_tool": opts.estimate_tool,
    }
    rep |= _choice(p, final, per_fold, names) | _figures(p, fr, fits, fin, h, scored)
    for k, reason in rep["not_estimated"].items():  # an offset a compliance moved (core.centred)
        if k in f.deltas:
            rep["not_estimated"][k] = (
                f"{reason}; written moved by its joint's compliance times the shift of its reference moment to the "
                f"mean moment arm over the data ({f.deltas[k][0]:.3g} {f.deltas[k][2]}): the offset of the arm at "
                "its mean load"
            )
    rep |= {
        "camera_model": final.candidate.camera,
        "camera_model_option": opts.camera,
        "camera_parameters": {k: {"value": f.deltas[k][0], "std_error": f.deltas[k][1]} for k in f.cam_names} or None,
        "sigma_pos_mm": float(fr.sig[-1, 0]),
        # which weights the user gave (--sigma-pos-mm / --sigma-rot-rad); the others are the data's
        "sigma_given": {"pos": opts.sigma_pos_mm is not None, "rot": opts.sigma_rot_rad is not None},
        "noise_pos_mm": noise,
        "sigma_rot_deg": float(np.degrees(fr.sig[-1, 1])) if p.n_points == 0 else None,
        "parameters": {
            k: {"value": v, "std_error": s, "unit": u} for k, (v, s, u) in f.deltas.items() if k not in f.cam_names
        },
        "estimated_dh": [names[i] for i in f.active if i < layout.n_kin],
        "unidentifiable": [n for n in p.ident.fixed_names if names.index(n) < layout.n_kin],
        "combinations": list(p.ident.combinations),
        "condition_number": core.condition_number(f.normal, f.active),
        "converged": bool(fin["converged"][0]),
        "steps": int(fin["steps"][0]),
        "base": frame_doc(f.model.robot.base),
        "tool": frame_doc(f.model.robot.tool),
        "training_ranges": training_ranges(robot, q, p.valid, file_units=True),
        "training_ranges_units": list(robot.units),  # the robot file's, not the data's ("units")
        # every option as given, and the plausibility limits as resolved for this robot and data:
        # what a rerun needs, and what the fit was judged against
        "options": dataclasses.asdict(opts),
        "plausibility_limits": _limits_doc(plausibility.Thresholds.of(robot, opts, q)),
        "plausible": not why,
        # judged where the solver stopped: when that is not a solution, that comes first
        "implausible": (
            why
            if not why or fin["converged"][0]
            else f"the final fit did not converge in {int(fin['steps'][0])} step(s); where it stopped: {why}"
        )
        or None,
        "likely_input_mistake": plausibility.names_a_cause(why),
        "notes": list(still_joint_notes(robot, q))
        + list(narrow_joint_notes(robot, q))
        + list(limit_notes(robot, q[p.valid], p.rows[p.valid]))
        + list(p.notes)
        + [n for n in [moved or _odd_point(p, h["pe"])] if n],
    }
    rep |= _outlier_section(p, fr, det, last, fin, h, reg, faults)
    if faults.any():
        rep["notes"].append(
            f"row(s) {', '.join(str(int(r)) for r in p.rows[faults])}: the points do not move as one rigid body "
            "(a marker slipped, was taken for another or seen through a reflection): measurement faults, not "
            "the arm's, so never counted as a region of its motion where it errs"
        )
    worse = [
        f"{what} {rep[k]:.3g} against {rep['frames_only_' + k]:.3g} mm"
        for what, k in (("new postures", "heldout_rms_mm"), ("beyond the training ranges", "extrapolation_rms_mm"))
        # by more than 1 %: their nested fits' figures differ by their choices
        if rep["selection"]["kept"] and np.isfinite(rep[k]) and rep[k] > rep["frames_only_" + k] * 1.01
    ]
    rep["worse_than_frames_only"] = (
        f"the calibrated model predicts postures held out worse than the nominal kinematics with the frames alone "
        f"({'; '.join(worse)}): these data do not support {rep['choice']!r}; "
        + ("frames alone (--params frames) predicts better" if p.auto else "--params auto chooses by these figures")
        if worse
        else None
    )
    if rep["worse_than_frames_only"]:
        rep["notes"].append(rep["worse_than_frames_only"])
    if drifted := _drift_doc(p, f.model):
        rep["notes"].append(_drift_note(drifted))
    rep["drift"] = drifted
    if region := rep["outlier_detection"]["region"]:
        rep["notes"].append(_region_note(p, region, kept=opts.keep_outliers))
    elif hint is not None:
        rep["notes"].append(_hint_note(p, _region_doc(p, hint, 0.0), rep["outlier_detection"]))
    if rep["cv_fits_converged"] < rep["cv_fits"]:  # the held-out figures come from these fits
        rep["notes"].append(
            f"{rep['cv_fits'] - rep['cv_fits_converged']} of the {rep['cv_fits']} cross-validation fits did not "
            f"converge (after Levenberg-Marquardt too): the held-out figures include where they stopped; raise "
            f"max_steps (--max-steps, {opts.max_steps})"
        )
    if back := rep["outlier_detection"]["taken_back_rows"]:
        rep["notes"].append(
            f"taken back: row(s) {', '.join(map(str, back))}, flagged by the outlier detection, are predicted "
            "by the calibrated model within the threshold in the spread of their own prediction, and fitted"
        )
    model = core.described(f.model, robot)
    if (bent := rigid_figures(model, p.data)) is not None:  # what the files other tools read hold
        rep["rms_mm_on_the_data_with_compliance"], rep["rigid_geometry_rms_mm_on_the_data"] = bent
        rep["notes"].append(
            f"the joint compliances are applied by jaxcal alone (evaluate, compensate, its TOML and URDF): a reader "
            f"of the rigid geometry (a UR kinematics file, a URDF in ROS or MoveIt, the DH table without its "
            f"compliance rows) predicts the data to {bent[1]:.3g} mm RMS, the model with them {bent[0]:.3g} mm "
            f"(every pose); compliance='no' (--compliance no) fits the best rigid model"
        )
    if p.n_points:
        rep["points_mm"] = np.asarray(f.model.points).tolist()
        rep["heldout_points_rms_mm"] = [float(v) for v in core.nan_rms(h["pe"][scored], 0)]
    per_pose = {
        "rows": p.rows,
        "frames_only_heldout": _squeeze(h["fo"]),
        "heldout": _squeeze(h["pe"]),
        "frames_only_train": _squeeze(np.asarray(fr.fit["pos_err"])[-1]),
        "train": _squeeze(fin["pos_err"][0]),
        "outlier": last.flags[0],
        "scored": scored,
        "sigmas": last.sigmas[0],
        "frames_only_heldout_rot": h["fre"],
        "heldout_rot": h["re"],
        "frames_only": core.described(fr.member(-1), robot).robot,
    }
    return DataCalibration(
        model=model, nominal=robot, choice=final.candidate, report=rep, per_pose=per_pose,
        deltas=f.deltas, covariance=f.cov, layout=layout, training_ranges=training_ranges(robot, q, p.valid),
    )  # fmt: skip
