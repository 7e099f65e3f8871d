"""Held-out evaluation of a saved model: predict a data file's measurements with the model as it
is (frames included, nothing re-fitted) and summarise the errors per point, per pose and by
posture group relative to the training data."""

from __future__ import annotations

import numpy as np
from jaxtyping import Float

from .._config import jit
from ..errors import DataError
from ..model import Model, predict
from ..robot import Robot
from ..solvers import OUTLIER_SIGMAS
from ._checks import as_target, check_units, joint_ranges, zero_points
from ._outliers import assess
from ._plausibility import RESIDUAL_SHARE, variants

_predict = jit(predict)  # one program, not one per operation

REPEAT_RAD = 1e-2
"""A pose whose every revolute joint is within this of a training pose's (and every prismatic
joint within :data:`REPEAT_MM`) repeats that posture."""
REPEAT_MM = 1.0
GROUPS = ("repeated", "new within training ranges", "out of training ranges")
ROTATION_DEG = 2.0
"""Rotation RMS beyond which errors are far beyond a calibration's (as ``max_rotation_deg``)."""
OUTSIDE_WARNING = 0.10
"""Share of postures outside the training ranges beyond which :func:`evaluate` warns."""


def _stats(err: np.ndarray) -> dict:
    """RMS, max and median of error norms (any shape; NaN, a lost point, left out), or ``None``
    entries without data."""
    e = np.ravel(err)
    e = e[np.isfinite(e)]
    if e.size == 0:
        return {"rms_mm": None, "max_mm": None, "median_mm": None}
    return {"rms_mm": float(np.sqrt(np.mean(e**2))), "max_mm": float(e.max()), "median_mm": float(np.median(e))}


def _within(q, lo, hi, tol, revolute) -> np.ndarray:
    """Whether each value of ``q`` lies in ``[lo - tol, hi + tol]``; a revolute joint's value
    also where a whole turn away (``q + 2 pi k``: the same posture, nothing extrapolated)."""
    q, lo, hi, tol = np.broadcast_arrays(*map(np.asarray, (q, lo, hi, tol)))
    turned = lo - tol + np.mod(q - (lo - tol), 2 * np.pi)  # the first turn of q at or above the range's start
    return np.where(revolute, turned <= hi + tol, (q >= lo - tol) & (q <= hi + tol))


def _gap(a, b, revolute) -> np.ndarray:
    """``|a - b|``, a revolute joint's the shorter way round."""
    d = np.abs(np.asarray(a) - np.asarray(b))
    return np.where(revolute, np.abs(np.mod(d + np.pi, 2 * np.pi) - np.pi), d)


def posture_groups(robot: Robot, q: np.ndarray, q_train: np.ndarray) -> np.ndarray:
    """Index into :data:`GROUPS` of every pose ``q (K, n)`` relative to the training poses: a
    repeat of one (within :data:`REPEAT_RAD` / :data:`REPEAT_MM` on every joint), a new posture
    with every joint inside the training data's range, or outside it on some joint. A revolute
    joint's reading a whole turn away is the same angle."""
    rev = np.array([t == "R" for t in robot.joint_types])
    tol = np.array([REPEAT_RAD if t == "R" else REPEAT_MM for t in robot.joint_types])
    near = np.all(_gap(q[:, None, :], q_train[None, :, :], rev) <= tol, axis=-1).any(axis=1)
    inside = np.all(_within(q, *joint_ranges(robot, q_train), tol, rev), axis=-1)
    return np.where(near, 0, np.where(inside, 1, 2))


def beyond(robot: Robot, q, ranges: dict) -> np.ndarray:
    """``(K, n)`` how far each joint value of ``q (K, n)`` lies beyond its training range
    (``ranges``: joint name -> ``(lowest, highest)``, mm and rad): 0 within it or within the
    tolerances :data:`REPEAT_RAD`, :data:`REPEAT_MM` of it, and for a joint without a range; a
    revolute joint's reading a whole turn away is inside, and its distance the shorter way round."""
    q = np.asarray(q, float)
    out = np.zeros(q.shape)
    for j, (name, t) in enumerate(zip(robot.joint_names, robot.joint_types)):
        if name not in ranges:
            continue
        tol = REPEAT_RAD if t == "R" else REPEAT_MM
        lo, hi = ranges[name]
        if t == "R":
            turned = lo - tol + np.mod(q[:, j] - (lo - tol), 2 * np.pi)  # the first turn at or above the range
            far = np.minimum(turned - hi, lo + 2 * np.pi - turned)
        else:
            far = np.maximum(lo - q[:, j], q[:, j] - hi)
        out[:, j] = np.where(far > tol, far, 0.0)
    return out


def outside_summary(robot: Robot, far: np.ndarray) -> dict:
    """``outside_training_ranges`` of :func:`evaluate` from the distances ``far (K, n)`` beyond the
    training ranges (:func:`beyond`): how many postures, which joints by how much (mm, rad), and
    how many with several joints out at once."""
    away = (far > 0).any(-1)
    return {
        "poses": int(away.sum()),
        "fraction": float(away.mean()) if len(away) else 0.0,
        "several_joints": int(((far > 0).sum(-1) >= 2).sum()),
        "joints": {
            robot.joint_names[j]: {"poses": int((far[:, j] > 0).sum()), "max_beyond": float(far[:, j].max())}
            for j in np.flatnonzero((far > 0).any(0))
        },
    }


def _outside_note(robot: Robot, summary: dict, n_poses: int) -> str:
    """The extrapolation warning, from :func:`outside_summary`."""
    kinds = dict(zip(robot.joint_names, robot.joint_types))
    joints = [
        f"{name} in {v['poses']} by up to "
        + (f"{np.degrees(v['max_beyond']):.3g} deg" if kinds[name] == "R" else f"{v['max_beyond']:.3g} mm")
        for name, v in summary["joints"].items()
    ]
    several = summary["several_joints"]
    return (
        f"{summary['poses']} of {n_poses} postures ({100 * summary['fraction']:.0f} %) have a joint outside the "
        f"ranges the model was fitted on ({'; '.join(joints)}"
        + (f"; {several} with two joints or more out at once" if several else "")
        + "): there it extrapolates, and errors grow; a calibration's figure beyond the ranges is for one joint "
        "at a time just past its range, and errors grow further with the distance and with several joints out"
    )


def _positions(pred, n_points: int):
    """The first measured point's (or the tool's) predicted positions ``(K, 3)``."""
    return pred[:, 0] if n_points else pred[:, :3, 3]


def _errors(pred, target, n_points: int):
    """``(position error norms (K, M) mm, rotation errors (K,) deg or None for points)`` of the
    predictions ``pred`` of ``target``."""
    if n_points:
        return np.linalg.norm(target - pred, axis=-1), None
    dR = np.einsum("kij,klj->kil", target[:, :3, :3], pred[:, :3, :3])
    rot = np.degrees(np.arccos(np.clip((np.trace(dR, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)))
    return np.linalg.norm(target[:, :3, 3] - pred[:, :3, 3], axis=-1)[:, None], rot


def _stand_out(pos: Float[np.ndarray, "K M"], rot: Float[np.ndarray, " K"] | None) -> tuple[np.ndarray, np.ndarray]:
    """``(flags (K,), sigmas (K,))``: the poses whose errors stand out of the others' as the
    outlier rule of a calibration judges a fit's residuals (:func:`._outliers.assess` at
    :data:`jaxcal.solvers.OUTLIER_SIGMAS`), from ``pos (K, M)`` mm and ``rot (K,)`` deg or None.
    A fit leaves such poses out; scored as they are, they can set a file's RMS alone."""
    seen = np.isfinite(pos)
    norms = np.sqrt(np.sum(np.where(seen, pos, 0.0) ** 2, -1))
    rn = np.zeros_like(norms) if rot is None else np.asarray(rot, float)

    def unit(x):  # in units of their median, as a fit's weighted rows are: the scale's floor then holds
        m = np.median(x[seen.any(-1)]) if seen.any() else 0.0
        return x / m if m > 0 else x

    fit = {"pos_norms": unit(norms)[None], "rot_norms": unit(rn)[None]}
    det = assess(fit, seen.any(-1)[None], 3 * seen.sum(-1), poses=rot is not None, sigmas=OUTLIER_SIGMAS)
    return det.flags[0], det.sigmas[0]


def _stand_out_note(rows, sigmas, pose_mm, rot_deg, pos, rot=None) -> str:
    """The warning naming the poses that stand out (each with its error, mm, and for poses deg:
    ``rot_deg``, or None), with the RMS of the others (mm; deg). The scale is the file's own
    median error: with reference data more precise than the model, a row can stand out at a few
    hundredths of a millimetre, which the figures show."""
    turns = [None] * len(rows) if rot_deg is None else rot_deg
    listed = ", ".join(
        f"{int(r)} ({u:.3g} sigma, {e:.3g} mm" + ("" if d is None else f", {d:.3g} deg") + ")"
        for r, u, e, d in list(zip(rows, sigmas, pose_mm, turns))[:10]
    )
    more = f" and {len(rows) - 10} more" if len(rows) > 10 else ""
    return (
        f"row(s) {listed}{more} stand out of the others' errors (in standard deviations of this file's errors, "
        f"their median taken as the noise, beyond the {OUTLIER_SIGMAS:g}-sigma rule calibrate leaves poses out "
        f"by): a measurement gone wrong (a swapped marker label, a knock), postures the model predicts badly, or "
        f"the rows its calibration left out as outliers; the figures include them; without them the position RMS "
        f"is {_stats(pos)['rms_mm']:.4g} mm"
        + ("" if rot is None else f" and the rotation RMS {_stats(rot)['rms_mm']:.4g} deg")
    )


def _rms(model: Model, q, target, n_points: int) -> tuple[float, float]:
    """Position RMS (mm) and rotation RMS (deg; 0 for points) of the model's errors."""
    pos, rot = _errors(np.asarray(_predict(model, q)), target, n_points)
    return float(np.sqrt(np.nanmean(pos**2))), 0.0 if rot is None else float(np.sqrt(np.mean(rot**2)))


def _far(model: Model, meas, pos, rot) -> list[str]:
    """A warning when the errors are far beyond a calibration's (:data:`RESIDUAL_SHARE` of the
    reach in position, :data:`ROTATION_DEG` in rotation), naming the input mistake that would
    explain them if one does (the mistakes :func:`._plausibility.variants` tries, each predicted
    with the model as it is; ``pos``, ``rot`` the RMS errors of the data as given)."""
    q, M = np.asarray(meas.q), meas.n_points
    limit = RESIDUAL_SHARE * model.robot.reach(q)
    if pos <= limit and rot <= ROTATION_DEG:
        return []
    tried = {m: _rms(model, qv, tv, M) for m, (qv, tv) in variants(model.robot, q, meas.measured, M).items()}
    best = min(tried, key=lambda m: max(tried[m][0] / limit, tried[m][1] / ROTATION_DEG))
    bp, br = tried[best]
    why = (
        f"read as if the file had {best}, it gives {bp:.3g} mm" + ("" if M else f", {br:.3g} deg")
        + ": check the file for that mistake"
        if bp <= limit and br <= ROTATION_DEG
        else "no common input mistake explains it (a measurement frame that moved since the calibration, "
        "or another robot's data?)"
    )  # fmt: skip
    if np.allclose(np.asarray(model.robot.base), np.eye(4)) and not (bp <= limit and br <= ROTATION_DEG):
        why += (
            "; the model's base is the identity (a robot file or a UR kinematics file holds no measurement "
            "frame): the data must then be in the robot's base frame, or evaluate the model calibrate "
            "writes (--out-robot, --out-model), which carries the frame"
        )
    size = f"{pos:.4g} mm" + ("" if M else f", {rot:.3g} deg") + " RMS"
    return [
        f"the errors ({size}) are far beyond a calibration's ({limit:.3g} mm, {100 * RESIDUAL_SHARE:g} % of the "
        f"reach" + ("" if M else f", {ROTATION_DEG:g} deg") + f"); {why}"
    ]


FAR_FROM_MEDIAN = 10.0
"""Once some rows err beyond a calibration's, rows beyond this many times the median row's error
are named with them: below the calibration line, they would still dominate the other rows' RMS."""


def _few(model: Model, meas, pos, rot=None) -> list[str]:
    """A warning naming the few rows whose errors (``pos (K, M)`` mm, ``rot (K,)`` deg for poses)
    are far beyond a calibration's while the median row's are within one, with those far beyond
    the median row (:data:`FAR_FROM_MEDIAN`): outliers of the file (a lost marker written as a
    number, swapped marker labels, a quaternion of another row, a knock), which no mistake of
    :func:`_far` (every row read wrong) explains, and the RMS over all rows hides."""
    limit = RESIDUAL_SHARE * model.robot.reach(np.asarray(meas.q))
    worst = np.nanmax(pos, -1)
    turn = np.zeros(len(worst)) if rot is None else np.asarray(rot)
    typical = np.median(worst) <= limit and np.median(turn) <= ROTATION_DEG  # the median row: a calibration's
    off_pos = typical and np.sqrt(np.nanmean(pos**2)) > limit
    off_rot = typical and np.sqrt(np.mean(turn**2)) > ROTATION_DEG
    if not (off_pos or off_rot):
        return []
    # beyond a calibration's, or far beyond the file's median row (hidden in "the other rows")
    line = min(limit, FAR_FROM_MEDIAN * np.median(worst)) if off_pos else limit
    line_rot = ROTATION_DEG  # not the median row's: poses simulated without rotation noise have none
    bad = np.flatnonzero((worst > line) | (turn > line_rot))
    if len(bad) == len(worst):  # every row: the file's doing (_far), not a few rows'
        return []
    bad = bad[np.argsort(-(np.maximum(worst[bad] / line, turn[bad] / line_rot) if off_rot else worst[bad]))]
    numbers = list(getattr(meas, "point_numbers", ()) or range(1, pos.shape[1] + 1))
    rows = meas.rows if getattr(meas, "rows", None) is not None else np.arange(1, len(worst) + 1)

    def points(k):  # every point of the row beyond the line, the worst first (two of a swapped pair)
        far = [j for j in np.argsort(-np.nan_to_num(pos[k], nan=-1.0)) if pos[k, j] > line]
        return f" point{'s' * (len(far) > 1)} {', '.join(str(numbers[j]) for j in far)}" if pos.shape[1] > 1 else ""

    size = (lambda k: f"{worst[k]:.3g} mm, {turn[k]:.3g} deg") if off_rot else (lambda k: f"{worst[k]:.3g} mm")
    where = [f"row {rows[k]}{points(k)} ({size(k)})" for k in bad[:5]]
    rest = f"{np.sqrt(np.nanmean(np.delete(pos, bad, 0) ** 2)):.3g} mm"
    rest += f", {np.sqrt(np.mean(np.delete(turn, bad) ** 2)):.3g} deg" if off_rot else ""
    limits = f"{limit:.3g} mm" + (f", {ROTATION_DEG:g} deg" if off_rot else "")
    below = (worst[bad] <= limit) & (turn[bad] <= ROTATION_DEG)
    return [
        f"{len(bad)} row(s) err far beyond a calibration's ({limits})"
        + ("" if not below.any() else f" or the median row's ({np.median(worst):.3g} mm)")
        + f": {', '.join(where)}"
        + (", ..." if len(bad) > 5 else "")
        + f"; the other rows score {rest} RMS. Outliers in this file (a lost marker written as a "
        f"number, swapped marker labels, {'a quaternion of another row, ' if off_rot else ''}a knock)?"
    ]


def _zeros(meas) -> list[str]:
    """A warning naming the rows with a position at exactly 0, 0, 0: a lost marker the export
    wrote as zeros, scored as a measurement."""
    zero = zero_points(meas.measured, meas.n_points).any(-1)
    numbers = np.arange(1, len(zero) + 1) if getattr(meas, "rows", None) is None else meas.rows
    rows = [int(r) for r, z in zip(numbers, zero) if z]
    if not rows:
        return []
    listed = ", ".join(map(str, rows[:10])) + (f" and {len(rows) - 10} more" if len(rows) > 10 else "")
    return [
        f"row(s) {listed}: a position at exactly 0, 0, 0, scored as measured (a lost marker written as zeros? "
        "export lost markers as empty cells)"
    ]


def evaluate(model: Model, meas, *, training=None, ranges: dict | None = None) -> dict:
    """Errors of ``model`` on the measurements ``meas`` (:class:`jaxcal.Measurements`), nothing
    fitted: JSON-ready, lengths in mm, angles in degrees.

    * ``position_rms_mm``, ``position_max_mm``, ``position_median_mm`` over every point of every
      pose (error norms), and ``points``: per measured point in column order, ``rms_mm``,
      ``max_mm``, ``median_mm`` and (points) ``point``, its number in the file;
    * ``rotation_rms_deg`` (and max, median) when poses are measured;
    * ``poses``: per pose its data row and error (mm; per point, None for a point not seen, and
      deg for poses); ``lost_points``: ``{row, point}`` of the points not seen, ``dropped_rows``
      the rows with none, ``ignored_columns`` the file's columns neither joints nor measurements;
    * ``groups`` (given the ``training`` measurements): the same summary for repeated postures,
      new ones within the training ranges and ones out of them;
    * ``outside_training_ranges`` (given ``ranges``, joint name -> ``(lowest, highest)`` mm and
      rad, as a calibrated model file records them, or the ``training`` data's): how many poses
      have a joint outside them, and ``warnings`` when more than :data:`OUTSIDE_WARNING` do: the
      model was not fitted there and extrapolates; and when the errors are far beyond a
      calibration's, with the input mistake that would explain them if one does;
    * ``outliers``: ``{row, sigmas}`` of the poses whose errors stand out of the others' by the rule
      a calibration leaves poses out by (worst first), ``without_outliers`` the position (and
      rotation) RMS, max and median without them, and a warning naming them (unless the rows far
      beyond a calibration's are named instead); the figures above include them.

    Joint values that look like degrees, and positions whose spread is not the model's (another
    length unit), are refused (:class:`jaxcal.DataError` naming the option), as by calibrate.

    A robot file without points measures its tool frame's origin: it evaluates one point.
    """
    M = meas.n_points
    if model.n_points == 0 and M == 1:
        model = Model(model.robot, np.zeros((1, 3)), model.camera_params, camera=model.camera)
    if model.n_points != M:
        have = "poses" if M == 0 else f"{M} point(s) per pose"
        want = "poses" if model.n_points == 0 else f"{model.n_points} point(s)"
        why = (
            " (it was calibrated from measured points: its tool's orientation was not; score the positions "
            "with a file of x, y, z)"
            if M == 0
            else " (choose the file's point it was fitted on: --points J)"
            if model.n_points == 1
            else f" (choose the file's {model.n_points} points it was fitted on: --points with the "
            f"{model.n_points} numbers calibrate was given)"
            if 1 < model.n_points < M
            else ""
        )
        raise DataError(f"{meas.source}: the data measure {have}, the model predicts {want}{why}", option="data")
    # the checks calibrate makes (finite values, a lost point NaN in all three coordinates, proper
    # rotations): a NaN joint or coordinate would otherwise leave a pose out of the figures unsaid
    numbers = tuple(getattr(meas, "point_numbers", ()))
    as_target(model.robot, meas.q, meas.measured, batched=False, rows=getattr(meas, "rows", None), numbers=numbers)
    q = np.asarray(meas.q)
    pred = np.asarray(_predict(model, q))
    # by the median spread, as calibrate: a row of a lost marker's sentinel is named below, not taken for a unit
    check_units(
        model.robot, q, meas.measured, M, batched=False, model_positions=_positions(pred, M), model="the model",
        robust=True,
    )  # fmt: skip
    pos, rot = _errors(pred, meas.measured, M)  # (K, M) mm, (K,) deg
    out = {"poses_evaluated": len(meas), "source": meas.source}
    out.update({f"position_{k}": v for k, v in _stats(pos).items()})
    numbers = list(getattr(meas, "point_numbers", ()) or range(1, M + 1))
    out["points"] = [_stats(pos[:, j]) | ({"point": numbers[j]} if M else {}) for j in range(pos.shape[1])]
    if rot is not None:
        out.update({f"rotation_{k.replace('_mm', '_deg')}": v for k, v in _stats(rot).items()})
    out["poses"] = [
        {"row": int(r), "error_mm": [float(v) if np.isfinite(v) else None for v in pos[i]]}
        | ({} if rot is None else {"rotation_deg": float(rot[i])})
        for i, r in enumerate(meas.rows)
    ]
    out["lost_points"] = [{"row": r, "point": j} for r, j in getattr(meas, "lost_points", [])]
    out["dropped_rows"] = [int(r) for r in getattr(meas, "dropped_rows", ())]
    out["ignored_columns"] = list(getattr(meas, "ignored", ()))  # as calibrate's report lists them
    if ranges is None and training is not None:
        lo, hi = joint_ranges(model.robot, training.q)
        ranges = {n: (float(a), float(b)) for n, a, b in zip(model.robot.joint_names, lo, hi)}
    rot_rms = 0.0 if rot is None else float(np.sqrt(np.mean(rot**2)))
    few = _few(model, meas, pos, rot)
    far = [] if few else _far(model, meas, float(np.sqrt(np.nanmean(pos**2))), rot_rms)
    if far and ranges is None and training is None:  # a model file calibrate wrote records its ranges
        far[0] += (
            "; if this model was never calibrated (a nominal table or URDF), errors of this size can be "
            "the arm's own geometric errors: calibrate it first"
        )
    out["warnings"] = _zeros(meas) + few + far
    flags, sigmas = _stand_out(pos, rot)
    order = np.argsort(-np.where(flags, sigmas, -np.inf))[: int(flags.sum())]  # the worst first
    pose_mm = np.sqrt(np.nanmean(pos**2, -1))  # a pose's RMS over its points, as calibrate lists it
    out["outliers"] = [
        {"row": int(meas.rows[k]), "sigmas": float(sigmas[k]), "position_mm": float(pose_mm[k])}
        | ({} if rot is None else {"rotation_deg": float(rot[k])})
        for k in order
    ]
    if flags.any() and not flags.all():
        kept = {f"position_{k}": v for k, v in _stats(pos[~flags]).items()}
        if rot is not None:
            kept |= {f"rotation_{k.replace('_mm', '_deg')}": v for k, v in _stats(rot[~flags]).items()}
        out["without_outliers"] = {"poses": int((~flags).sum())} | kept
        if not few:  # else named as rows far beyond a calibration's
            out["warnings"].append(
                _stand_out_note(
                    np.asarray(meas.rows)[order],
                    sigmas[order],
                    pose_mm[order],
                    None if rot is None else rot[order],
                    pos[~flags],
                    None if rot is None else rot[~flags],
                )
            )
    if ranges is not None:
        summary = outside_summary(model.robot, beyond(model.robot, meas.q, ranges))
        out["outside_training_ranges"] = summary
        if summary["fraction"] > OUTSIDE_WARNING:
            out["warnings"].append(_outside_note(model.robot, summary, len(meas.q)))
    if training is not None:
        if training.q.shape[1] != meas.q.shape[1]:
            raise DataError(f"{training.source}: {training.q.shape[1]} joints, the data {meas.q.shape[1]}")
        g = posture_groups(model.robot, np.asarray(meas.q), np.asarray(training.q))
        out["groups"] = {
            name: {"poses": int(np.sum(g == i))} | {f"position_{k}": v for k, v in _stats(pos[g == i]).items()}
            for i, name in enumerate(GROUPS)
        }
    return out


def rigid_figures(model: Model, meas) -> tuple[float, float] | None:
    """``(position RMS with the joint compliances, position RMS of the rigid geometry alone)``
    (mm, every pose of ``meas``) of a model with compliances, which only jaxcal's own readers
    apply (a URDF in ROS, a UR kinematics file, a DH table read without its compliance rows see
    the rigid geometry); None for a rigid model."""
    c = model.robot.compliance
    if c is None or not np.any(np.asarray(c) != 0):
        return None
    alone = Model(
        model.robot.replace(compliance=None, load=None), model.points, model.camera_params, camera=model.camera
    )
    q, target, M = np.asarray(meas.q), np.asarray(meas.measured), meas.n_points
    return _rms(model, q, target, M)[0], _rms(alone, q, target, M)[0]  # the errors alone, none of evaluate's checks
