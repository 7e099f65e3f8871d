"""Checks of calibration data before anything is fitted: shapes, finite values, rigid poses,
and evidence of a length unit that is not the robot's."""

from __future__ import annotations

import numpy as np
from jaxtyping import Bool, Float, Int

from .._config import as_f64
from ..errors import DataError
from ..robot import LENGTH_UNITS, Robot


def _dtype(a):
    try:
        return np.asarray(a).dtype
    except ValueError:  # ragged: as_f64 names it
        return None


def as_target(
    robot: Robot,
    q,
    measured,
    *,
    batched: bool,
    position_only: bool | None = None,
    rows: Int[np.ndarray, " K"] | None = None,
    numbers: tuple[int, ...] = (),
):
    """Validate ``q`` and the measurements; return ``(q, target, n_points)`` as float64 NumPy
    arrays (copies: the caller's arrays are never touched).

    Measurements as users have them: positions ``(K, 3)``, points ``(K, M, 3)`` (several points
    on the tool per pose; a point lost at a pose is NaN in its three coordinates, and every
    pose keeps at least one) or poses ``(K, 4, 4)`` (``position_only=True`` keeps their
    translations); with a leading data-set axis when ``batched`` (where a data set may miss a
    point, or have a pose of no point, or a pose NaN in its top three rows: not measured,
    :func:`lost_points`).
    """
    if not isinstance(robot, Robot):
        raise DataError(f"robot must be a jaxcal.Robot, got {type(robot).__name__}", option="robot")
    for name, a in (("q", q), ("measured", measured)):  # True/False are no joint values or lengths
        if _dtype(a) == np.bool_:
            raise DataError(f"{name}: expected real numbers, got booleans", option=name)
    q = np.array(as_f64(q, "q"))
    measured = np.array(as_f64(measured, "measured"))
    lead = 2 if batched else 1
    shape_q = "(R, K, n)" if batched else "(K, n)"
    if q.ndim != lead + 1 or q.shape[-1] != robot.n_joints:
        raise DataError(f"q must have shape {shape_q} with n = {robot.n_joints} joints, got {q.shape}", option="q")
    K = q.shape[:-1]
    if measured.shape == K + (4, 4):
        kind = "poses"
    elif measured.shape == K + (3,):
        kind = "positions"
        measured = measured[..., None, :]
    elif measured.ndim == lead + 2 and measured.shape[:lead] == K and measured.shape[-1] == 3:
        kind = "points"
    else:
        raise DataError(
            f"measured must have shape {K + (4, 4)} (poses), {K + (3,)} (positions) or "
            f"{K + ('M', 3)} (M points per pose), one per row of q; got {measured.shape}",
            option="measured",
        )
    if kind == "poses":  # a pose not measured is NaN in its rotation and translation
        gone = np.isnan(measured[..., :3, :]).all((-1, -2))
        lost, unseen = np.broadcast_to(gone[..., None], measured.shape[:-1]), gone.all(-1)
    else:
        lost = np.isnan(measured).all(-1)
        gone, unseen = lost_points(measured)
    for name, arr in (("q", q), ("measured", np.where(lost[..., None], 0.0, measured))):
        bad = ~np.isfinite(arr)
        if bad.any():
            idx = tuple(int(i) for i in np.argwhere(bad)[0])
            what = "; a point not measured is NaN in all three coordinates" if kind != "poses" and name != "q" else ""
            value, where = arr[idx], _place(robot, name, kind, idx, rows, batched, numbers)
            raise DataError(
                f"{name}: non-finite value ({value}) at {where}{what}; {int(bad.sum())} non-finite value(s) in all",
                option=name,
            )
    # a marker never measured makes every fit singular; in a batch, only one never measured in any
    # data set (a data set missing it, or with a pose of no point, is calibrate_batch's to handle)
    never = unseen.all(0) if batched else unseen
    if kind == "points" and never.any():
        j = [int(i) + 1 for i in np.flatnonzero(never)]
        where = " of any data set" if batched else ""
        raise DataError(
            f"measured: point(s) {', '.join(map(str, j))} not seen at any pose{where} (all NaN, empty in the "
            f"file); leave them out (choose the measured points with --points / Measurements.select_points)",
            option="points",
        )
    if gone.any() and not batched:
        idx = tuple(int(i) for i in np.argwhere(gone)[0])
        raise DataError(
            f"measured{list(idx)}: no {'pose' if kind == 'poses' else 'point'} measured at this pose (all NaN); "
            "leave the pose out",
            option="measured",
        )
    check_angles(robot, q, rows)
    if kind == "poses":
        bad_row = (np.abs(measured[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max(-1) > 1e-9) & ~gone
        if bad_row.any():
            idx = tuple(int(i) for i in np.argwhere(bad_row)[0])
            raise DataError(
                f"measured{list(idx)}: bottom row is {measured[idx][3].tolist()}, not [0, 0, 0, 1]", option="measured"
            )
        if position_only:
            return q, measured[..., None, :3, 3], 1
        R = measured[..., :3, :3]
        err = np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)).max((-1, -2))
        bad_rot = (err > 1e-6) | (np.linalg.det(R) < 0)
        if bad_rot.any():
            idx = tuple(int(i) for i in np.argwhere(bad_rot)[0])
            why = (
                f"|R R^T - I| = {err[idx]:.3g}"
                if err[idx] > 1e-6
                else "its determinant is -1, a reflection: a left-handed frame, or one axis flipped"
            )
            raise DataError(
                f"measured{list(idx)}: rotation is not a proper rotation matrix ({why}); "
                f"{int(bad_rot.sum())} such pose(s); use position_only=True if only positions were measured",
                option="measured",
            )
        return q, measured, 0
    return q, measured, measured.shape[-2]


def _place(robot: Robot, name: str, kind: str, idx: tuple[int, ...], rows, batched: bool, numbers=()) -> str:
    """Where a value sits, in the user's words: the data set, the pose (its file row when known),
    the joint, the point (its number in the file, ``numbers``, when known) and the coordinate."""
    lead = [f"data set {idx[0]}"] if batched else []
    pose = idx[len(lead)]
    lead.append(f"row {np.asarray(rows)[pose]}" if rows is not None and not batched else f"pose index {pose}")
    rest = idx[len(lead) :]
    if name == "q":
        return ", ".join(lead + [f"joint {robot.joint_names[rest[0]]!r}"])
    if kind == "poses":
        return ", ".join(lead + [f"matrix element [{rest[0]}][{rest[1]}]"])
    point = [f"point {numbers[rest[0]] if numbers else rest[0] + 1}"] if kind == "points" else []
    return ", ".join(lead + point + ["xyz"[rest[-1]]])


def lost_points(target: Float[np.ndarray, "*R K M 3"]) -> tuple[Bool[np.ndarray, "*R K"], Bool[np.ndarray, "*R M"]]:
    """The poses with no point measured, and the points never measured, of point measurements
    (NaN in all three coordinates where a point was lost), with or without a data-set axis."""
    lost = np.isnan(target).all(-1)
    return lost.all(-1), lost.all(-2)


START_SPREAD_LIMIT = 30.0
"""A start fitted to the data whose points spread more than this many times the nominal model's
does not vouch for the data's unit when the data spread :data:`UNIT_RATIO` times the nominal's
(:func:`check_units`): a tool 1000x the arm, as another length unit needs, is no evidence (a
marker far out on a flange that barely moves, a pan-tilt head, spreads tens of times wider)."""
UNIT_RATIO = 100.0
PRISMATIC_UNIT_FACTOR = 100.0
"""A prismatic joint's values beyond this many times its limits' magnitude, in most poses, are in
another length unit (a factor of 1000 between mm and m)."""


ARM_REACH_MM = (5.0, 2e4)
"""A robot whose reach (:meth:`jaxcal.Robot.reach`) lies outside this range (mm) is no arm in the
unit its file names: a unit refusal then names the robot file's unit too."""
BEYOND_LIMIT = 1e-6
"""A reading beyond its joint's limit by more than this share of the limit (in the robot file's
unit, at least one of it) lies outside them; less is the limit written with rounding."""


def limit_notes(
    robot: Robot,
    q: Float[np.ndarray, "K n"],
    rows: Int[np.ndarray, " K"] | None = None,
    *,
    poses: Int[np.ndarray, " K"] | None = None,
) -> tuple[str, ...]:
    """A note per joint with limits of its own that some poses lie beyond: the readings or the
    limits are wrong, and where most poses lie beyond them, the limits may be in another unit
    than the robot file says. ``rows``: the poses' row numbers in a data file; without, they are
    named by their indices ``poses`` (default ``0..K-1``)."""
    q = np.asarray(q)
    scale = robot.joint_scale()
    lim = np.asarray(robot.q_limits) / scale[:, None]  # the file's units, as the note gives them
    v = q / scale
    slack = BEYOND_LIMIT * np.maximum(np.abs(lim), 1.0)
    beyond = ((v < lim[:, 0] - slack[:, 0]) | (v > lim[:, 1] + slack[:, 1])) & robot.limits_given()
    label, names = ("row(s)", np.asarray(rows)) if rows is not None else ("pose(s)", np.arange(len(q)))
    names = names if poses is None else np.asarray(poses)
    out = []
    for j in np.flatnonzero(beyond.any(0)):  # few joints: each its own note
        unit = robot.units[1] if robot.joint_types[j] == "R" else robot.units[0]
        k = np.flatnonzero(beyond[:, j])
        listed = ", ".join(map(str, names[k[:8]])) + (f" and {len(k) - 8} more" if len(k) > 8 else "")
        note = (
            f"joint {j + 1} ({robot.joint_names[j]}): {label} {listed} lie beyond its limits in the robot file "
            f"([{lim[j, 0]:.8g}, {lim[j, 1]:.8g}] {unit}; readings {v[k, j].min():.8g} to {v[k, j].max():.8g}): the "
            "model is fitted there, compensate flags commands beyond the limits; check the readings or the limits"
        )
        if len(k) > len(q) / 2:
            note += f" (most lie beyond them: are the limits in another unit than the file's {unit}?)"
        out.append(note)
    return tuple(out)


MOVED_SPAN_RAD = 0.5
"""A revolute column that spans less than this tells nothing of its unit (a joint held still, or
nearly): the degrees hint by column needs every other revolute joint to span more, and at most
pi (a column of degrees spanning a few degrees reads as a few radians)."""


def check_angles(robot: Robot, q, rows: Int[np.ndarray, " K"] | None = None) -> None:
    """Refuse joint angles that look like degrees: revolute values beyond both a full turn and
    the joint limits in most poses (a few such poses are left to the fit and its checks). A
    joint whose limits are the default ones may be a continuous joint turning several times: the
    message says so, since its values may be radians. Prismatic values far beyond their given
    limits in most poses are refused too (:data:`PRISMATIC_UNIT_FACTOR`): a positions check
    cannot see millimetres read as metres when the points are scaled with the joint. ``rows``:
    the poses' row numbers in the data file, to name one."""
    _prismatic_units(robot, np.asarray(q), rows)
    revolute = np.array([t == "R" for t in robot.joint_types])
    if not revolute.any() or q.shape[-2] < 3:
        return
    limits = np.asarray(robot.q_limits)
    over = (np.abs(q) > np.maximum(2 * np.pi, np.abs(limits).max(axis=1)) * 1.05) & revolute
    frac = over.any(-1).mean(-1)
    if np.any(frac > 0.5):
        idx = tuple(int(i) for i in np.argwhere(over)[0])
        name = robot.joint_names[idx[-1]]
        where = (
            f"row {np.asarray(rows)[idx[0]]}, joint {name!r}" if rows is not None and q.ndim == 2 else f"q{list(idx)}"
        )
        unit = robot.units[1]
        turns = (
            f"; if joint {name!r} is a continuous joint whose readings run over several "
            "turns, they are radians: give it limits that cover them in the robot file"
            if not robot.limits_given()[idx[-1]]
            else ""
        )
        # some columns beyond in most poses, the other revolute ones within a turn's span (as
        # radians are): the file may mix units by column
        flat, n = q.reshape(-1, q.shape[-1]), q.shape[-1]
        cols = over.reshape(-1, n).mean(0) > 0.5
        span = np.ptp(flat, axis=0)
        # every other revolute joint moves (a joint held still tells no unit) within half a turn:
        # radians, surely; within a turn and never beyond it, likely (degrees moving that little
        # would be a few degrees' motion), so both readings are offered
        others = revolute & ~cols
        moving = others & ~over.reshape(-1, n).any(0) & (span > MOVED_SPAN_RAD)
        listed = ", ".join(repr(robot.joint_names[j]) for j in np.flatnonzero(cols))
        whole = f'if the data are in degrees, read them with angle_unit="deg"{turns}'
        if cols.any() and others.any() and ((moving & (span <= np.pi)) == others).all():
            advice = (
                f"{whole}; only joint(s) {listed} look so, the other revolute joints' values span less than half "
                "a turn: if only those columns are in degrees, convert them"
            )
        elif cols.any() and others.any() and (moving == others).all():
            advice = (
                f"joint(s) {listed} are beyond a turn in most poses, the other revolute joints never: if only "
                f"those columns are in degrees, convert them (angle_unit reads every joint column in one unit); "
                f"{whole}"
            )
        else:
            advice = whole
        raise DataError(
            f"{'q: ' if rows is None else ''}joint values look like degrees: {100 * float(np.max(frac)):.0f}% of the "
            "poses have a "
            f"revolute joint beyond a full turn and its limits ({where} = {q[idx]:.6g} rad); the "
            f"robot's angles are in {unit}; {advice}",
            option="angle_unit",
        )


def _prismatic_units(robot: Robot, q: np.ndarray, rows=None) -> None:
    prismatic = np.array([t == "P" for t in robot.joint_types]) & robot.limits_given()
    if not prismatic.any() or q.shape[-2] < 3:
        return
    size = np.abs(np.asarray(robot.q_limits)).max(axis=1)
    over = (np.abs(q) > PRISMATIC_UNIT_FACTOR * np.maximum(size, 1e-9)) & prismatic
    frac = over.mean(-2).reshape(-1, q.shape[-1]).max(0)  # per joint, the worst data set of a batch
    if np.any(frac > 0.5):
        j = int(np.argmax(frac))
        lu = LENGTH_UNITS[robot.units[0]]  # in the robot's unit, which the data were read in
        lo, hi = np.asarray(robot.q_limits)[j] / lu
        first = ""
        if rows is not None and q.ndim == 2:  # a data file's: its first such row, to look at
            k = int(np.flatnonzero(over[:, j])[0])
            first = f"; first at row {np.asarray(rows)[k]}: {q[k, j] / lu:.6g} {robot.units[0]}"
        raise DataError(
            f"{'q: ' if rows is None else ''}prismatic joint {robot.joint_names[j]!r} is beyond "
            f"{PRISMATIC_UNIT_FACTOR:g} times its limits [{lo:.6g}, {hi:.6g}] {robot.units[0]} in "
            f"{100 * float(frac[j]):.0f}% of the poses (up to {np.abs(q[..., j]).max() / lu:.6g} "
            f"{robot.units[0]}{first}): lengths in another unit than the robot's? Give "
            f"the data's unit (length_unit), or, if only this joint's column is in another unit, convert it",
            option="length_unit",
        )


def joint_ranges(robot: Robot, q: Float[np.ndarray, "K n"]) -> tuple[np.ndarray, np.ndarray]:
    """``(lowest (n,), highest (n,))`` of the readings ``q`` (mm, rad). A revolute joint that can
    turn a whole turn (no limits of its own, or limits a turn apart) has the shortest arc that
    holds every reading, starting in ``[-pi, pi)``, where that is shorter than their span: a
    continuous joint read over ``[0, 2 pi)`` visits the arc across 0, not the span between
    (:func:`._evaluate.beyond` reads a range a whole turn round)."""
    q = np.asarray(q, float)
    lo, hi = q.min(0), q.max(0)
    lim = np.asarray(robot.q_limits, float)
    turns = ~robot.limits_given() | (lim[:, 1] - lim[:, 0] >= 2 * np.pi - 1e-9)
    for j, t in enumerate(robot.joint_types):
        if t != "R" or not turns[j] or len(q) < 2:
            continue
        a = np.sort(np.mod(q[:, j], 2 * np.pi))
        gaps = np.diff(np.r_[a, a[0] + 2 * np.pi])
        i = int(np.argmax(gaps))
        arc = 2 * np.pi - gaps[i]
        if arc < hi[j] - lo[j] - 1e-9:
            start = a[(i + 1) % len(a)]
            lo[j] = start - 2 * np.pi if start >= np.pi else start
            hi[j] = lo[j] + arc
    return lo, hi


def unwrapped(robot: Robot, q: Float[np.ndarray, "K n"]) -> np.ndarray:
    """``q`` with each joint's readings within its :func:`joint_ranges` range: a joint that turns a
    whole turn read on the arc it visited (``lo + mod(q - lo, 2 pi)``), the others as they are."""
    q = np.array(q, float)
    lo, hi = joint_ranges(robot, q)
    arc = (np.asarray(robot.joint_types) == "R") & (hi - lo < np.ptp(q, 0) - 1e-9)
    q[:, arc] = lo[arc] + np.mod(q[:, arc] - lo[arc], 2 * np.pi)
    return q


def positions_of(target, n_points: int):
    """Measured positions ``(..., K, 3)``: the tool origin of poses, the first point of points."""
    return target[..., :3, 3] if n_points == 0 else target[..., 0, :]


def zero_points(target, n_points: int) -> np.ndarray:
    """``(K, M)`` the points (the tool origin of poses: ``M`` 1) measured at exactly 0, 0, 0: a lost
    marker an export wrote as zeros."""
    pts = np.asarray(target)[:, None, :3, 3] if n_points == 0 else np.asarray(target)
    return np.all(pts == 0.0, -1)


RADIANS_AS_DEGREES_SPAN = np.radians(20.0)
"""Revolute joints that all span less than this (rad), with positions that spread unlike the
model's: angles in radians read as degrees (limits of +-pi then span 6.3 deg, +-2 pi 12.6 deg).
It only names the likely cause: such data are refused either way."""


def check_units(
    robot: Robot,
    q,
    target,
    n_points: int,
    *,
    batched: bool,
    model_positions,
    robust: bool = False,
    what: str = "measured",
    model: str = "the nominal model",
    also=None,
) -> None:
    """Refuse a length-unit mismatch: the spread of the measured points (RMS distance to their
    centroid, independent of the unknown measurement frame) must be within 3x of the nominal
    model's at the same joint values; metres read as mm give 1000x. ``model_positions`` are the
    nominal model's tool positions at ``q``. ``robust``: the median distance to the median point
    instead, for rows that may hold a few wild values (a lost marker's sentinel, an unreachable
    target), which the detection or the solver then names; ``what`` and ``model`` name the rows
    and the model in the message. ``also``: a second model's positions (the nominal's, beside a
    start fitted to the data, which a wild row can pull): refused only when neither spread agrees,
    or when the data spread another unit's factor beyond the nominal's and the start agrees only
    by a tool far beyond the arm (:data:`START_SPREAD_LIMIT`)."""
    Q = q if batched else q[None]
    P_mea = positions_of(target if batched else target[None], n_points)
    P_mod = model_positions if batched else model_positions[None]
    if Q.shape[1] < 2:
        return

    seen = np.isfinite(P_mea).all(-1, keepdims=True)  # a lost first point: that pose left out of both

    def spread(P):
        P = np.where(seen, P, np.nan)
        if robust:
            return np.nanmedian(np.linalg.norm(P - np.nanmedian(P, -2, keepdims=True), axis=-1), -1)
        return np.sqrt(np.nanmean(np.sum((P - np.nanmean(P, -2, keepdims=True)) ** 2, -1), -1))

    s_mod, s_mea = spread(np.asarray(P_mod)), spread(P_mea)
    s_also = s_mod if also is None else spread(np.asarray(also if batched else np.asarray(also)[None]))
    around = "from their median point (median distance)" if robust else "around their centroid"
    lu = robot.units[0]
    revolute = np.array([t == "R" for t in robot.joint_types])

    def off(a, b):
        return a > 1.0 and not (a / 3.0 <= b <= 3.0 * a)

    for i, (a, b) in enumerate(zip(s_mod, s_mea)):
        # a start fitted to the data agrees with them by any tool: one that stretches the arm's
        # spread far beyond the nominal's (a tool 1000x the arm) is no evidence
        stretched = also is not None and a > START_SPREAD_LIMIT * s_also[i] and b > UNIT_RATIO * s_also[i]
        if (off(a, b) or stretched) and off(s_also[i], b):
            a = a if also is None else s_also[i]  # the message's figure is the nominal's, as it says
            where = f" (data set {i})" if batched else ""
            ratio = b / a
            span = float(np.ptp(Q[i][:, revolute], axis=0).max()) if revolute.any() else np.inf
            if 0.01 <= ratio <= 100 and span < RADIANS_AS_DEGREES_SPAN:  # the arm barely moves: angles misread
                raise DataError(
                    f"{what}{where}: positions spread {b:.4g} mm {around}, {model}'s "
                    f"{a:.4g} mm at the same joint values, whose revolute joints span at most "
                    f"{np.degrees(span):.3g} deg: joint angles look like radians read as degrees; the robot's "
                    f'angles are in {robot.units[1]}; read the data with angle_unit="rad"',
                    option="angle_unit",
                )
            guess, fix = (
                ("metres read as millimetres", ' length_unit="m"')
                if ratio < 0.01
                else ("millimetres read as metres", ' length_unit="mm"')
                if ratio > 100
                else ("a unit or scale that is not the robot's", " the unit they were written in")
            )
            # no arm reaches over 20 m or under 5 mm: the robot file's unit is as likely
            size = robot.reach()
            arm = (
                f"; or the robot file's lengths are not in {lu}: as written, the arm reaches {size:.4g} mm"
                if not ARM_REACH_MM[0] <= size <= ARM_REACH_MM[1]
                else ""
            )
            raise DataError(
                f"{what}{where}: positions spread {b:.4g} mm {around}, {model}'s "
                f"{a:.4g} mm at the same joint values ({ratio:.3g}x): lengths look like {guess}"
                f"; the robot's lengths are in {lu}; read the data with{fix}{arm}",
                option="length_unit",
            )


RIGID_RATIO = 20.0
"""Without the joint values: a pair of measured points keeps its distance when the distance's
robust spread over the rows is within this many times the steadiest pair's (their noise) or
:data:`RIGID_FLOOR_MM`. With them, the joint angles judge alone (:func:`_follows_posture`): a
marker noisier than the others spreads too. A marker that slipped partway is left to the fit's
own finding (:mod:`._markers`), which names the row."""
RIGID_FLOOR_MM = 0.1
RIGID_MIN_ROWS = 8
"""Rows a pair must be seen together in to be judged."""
FEW_JOINTS = 3
"""With too few rows for every joint's features, the last this many moving joints' are asked."""
POSTURE_P = 1e-6
"""A pair's distance follows the posture when the joint angles' first harmonics explain its
change at this significance (F test) or beyond; the change must also exceed the pair's own
scatter about them and three times the steadiest pair's spread (a noisy marker is not a loose one)."""


def _robust_spread(d) -> float:
    """1.4826 x the median absolute deviation: a normal deviation's sigma, robust to odd rows."""
    return float(1.4826 * np.median(np.abs(d - np.median(d))))


def _follows_posture(d, X, ref: float, X_few=None) -> float | None:
    """The RMS change (mm) of one pair's distances ``d`` that the posture features ``X`` explain
    (:data:`POSTURE_P`), or 0: a point on another link than the others moves against them with
    the joints between, as the cosine and sine of their angles. Rows beyond six robust spreads
    from the median (an outlier row, a label swapped) are left out first. Too few rows for
    every joint's, ``X_few`` (the last joints': a marker on a link near the tool) is asked; None
    where they are too few for that too."""
    from scipy.special import betainc  # the F tail; scipy.stats would cost a cold start 0.4 s

    med = np.median(d)
    keep = np.abs(d - med) <= 6.0 * _robust_spread(d) + 1e-12
    d, X = d[keep], X[keep]
    n, m = X.shape
    if n < m + 10 and X_few is not None:
        X = X_few[keep]
        m = X.shape[1]
    if n < m + 10 or m < 2:  # (no joint moves: nothing to explain a change by)
        return None
    fitted = X @ np.linalg.lstsq(X, d, rcond=None)[0]
    rss1, rss0 = np.sum((d - fitted) ** 2), np.sum((d - d.mean()) ** 2)
    if not rss0 > 0:
        return 0.0
    F = ((rss0 - rss1) / (m - 1)) / max(rss1 / (n - m), 1e-300)
    change = float(np.sqrt(np.mean((fitted - d.mean()) ** 2)))
    scatter = float(np.sqrt(rss1 / (n - m)))
    tail = betainc((n - m) / 2, (m - 1) / 2, (n - m) / (n - m + (m - 1) * F))  # P(F' > F), F(m-1, n-m)
    if tail < POSTURE_P and change > max(3.0 * ref, RIGID_FLOOR_MM, scatter):
        return change
    return 0.0


def check_rigid_points(
    target: Float[np.ndarray, "K M 3"], q=None, revolute=None, numbers: tuple[int, ...] = ()
) -> None:
    """Refuse measured points that do not keep their distances to the others as the joints move
    (a marker on another link): one tool cannot carry them, and a fit would spread their error
    over the arm's parameters. Model-free: given the joint values ``q (K, n)`` and which joints
    are ``revolute``, each pair's distance and the change of it the posture explains
    (:func:`_follows_posture`; a pair seen together in too few rows is no evidence); without
    them, its spread robust to the odd outlier row against the steadiest pair's
    (:data:`RIGID_RATIO`). Points that do keep them form groups; a group apart from the largest,
    by pairs judged, is refused, naming it. A marker that wobbles at random, or labels swapped in
    some rows, are left to the fit (outliers, label swaps). ``target`` in mm (NaN where not
    seen); ``numbers`` the file's point numbers."""
    P = np.asarray(target, float)
    if P.ndim != 3 or P.shape[1] < 3:
        return
    M = P.shape[1]
    nums = list(numbers) if len(numbers) == M else list(range(1, M + 1))
    X = None
    if q is not None:
        q = np.asarray(q, float)
        rev = np.ones(q.shape[1], bool) if revolute is None else np.asarray(revolute, bool)
        moving = np.ptp(q, axis=0) > 1e-9

        def features(cols):
            r, p = cols & rev, cols & ~rev
            return np.concatenate([np.ones((len(q), 1)), np.cos(q[:, r]), np.sin(q[:, r]), q[:, p]], 1)

        X = features(moving)
        last = np.zeros_like(moving)
        last[np.flatnonzero(moving)[-FEW_JOINTS:]] = True
        X_few = features(last)
    spread, change = np.full((M, M), np.nan), np.full((M, M), np.nan)
    seen = []
    for j in range(M):
        for k in range(j + 1, M):
            d = np.linalg.norm(P[:, j] - P[:, k], axis=-1)
            both = np.isfinite(d)
            if both.sum() >= RIGID_MIN_ROWS:
                spread[j, k] = spread[k, j] = _robust_spread(d[both])
                seen.append((j, k, both))
    if not seen:
        return
    ref = float(np.nanmin(spread))
    limit = max(RIGID_RATIO * ref, RIGID_FLOOR_MM)
    if X is not None:
        for j, k, both in seen:
            d = np.linalg.norm(P[both, j] - P[both, k], axis=-1)
            c = _follows_posture(d, X[both], ref, X_few[both])
            change[j, k] = change[k, j] = np.nan if c is None else c
    # where the posture can be asked, it alone judges (a marker noisier than the others spreads
    # too, and does not follow the joints), and a pair seen in too few rows to ask it is no
    # evidence; without joint values, the spread against the steadiest pair's
    if X is None:
        keeps = spread <= limit
    else:
        keeps = np.isfinite(change) & (change == 0)
        spread = np.where(np.isfinite(change), spread, np.nan)  # the pairs not judged: as never seen
    group = list(range(M))  # union-find over the pairs that keep their distance

    def root(i):
        while group[i] != i:
            i = group[i]
        return i

    for j, k in zip(*np.nonzero(keeps)):
        group[root(j)] = root(k)
    groups = {}
    for i in (i for i in range(M) if np.any(np.isfinite(spread[i]))):
        groups.setdefault(root(i), []).append(i)
    if not groups:  # no pair judged (rows too few to ask the posture)
        return
    parts = sorted(groups.values(), key=lambda g: (-len(g), g))
    main = parts[0]
    # a group apart only where the data hold a pair of it with the largest one, measured together
    apart = [g for g in parts[1:] if np.any(np.isfinite(spread[np.ix_(g, main)]))]
    if not apart:
        return
    rest = [i for g in apart for i in g]
    tie = len(apart[0]) == len(main)
    across = (spread[np.ix_(rest, main)], change[np.ix_(rest, main)])
    inside = spread[np.ix_(main, main)][np.triu_indices(len(main), 1)] if len(main) > 1 else np.array([np.nan])

    def listed(idx):
        return ", ".join(str(nums[i]) for i in idx)

    def span(v):
        v = v[np.isfinite(v) & (v > 0)]
        if not len(v):
            return "?"
        return f"{v.min():.3g}" if np.isclose(v.min(), v.max()) else f"{v.min():.3g}-{v.max():.3g}"

    one = "s" if len(rest) > 1 else ""
    who = (
        f"points {listed(main)} and point{one} {listed(rest)} do not keep their distances to each other"
        if tie
        else f"point{one} {listed(rest)} do{'es' if not one else ''} not keep {'their' if one else 'its'} distances "
        f"to points {listed(main)}"
    )
    follows = span(across[1])
    keep = " or ".join(
        f"--points {','.join(str(nums[i]) for i in sorted(g))}" for g in ([main, *apart] if tie else [main])
    )
    raise DataError(
        f"{who} over the rows: those distances spread by {span(across[0])} mm (robust, over the rows where both are "
        f"seen)"
        + (f" and follow the joint angles by {follows} mm RMS" if follows != "?" else "")
        + f", the others by {span(inside)} mm. One tool cannot carry them all: a marker on another link, or loose? "
        f"Check the markers, or calibrate with the points that move together ({keep})",
        option="points",
    )


def duplicate_rows_note(q, target, rows) -> tuple[str, ...]:
    """A note naming rows that repeat another row to the last digit, joints and measurements alike
    (a noisy instrument never reads a posture twice the same: a row written twice?), or ``()``.
    Each copy weighs as a measurement of its own (the folds keep a posture's rows together)."""
    K = len(q)
    flat = np.concatenate([np.asarray(q, float).reshape(K, -1), np.asarray(target, float).reshape(K, -1)], 1)
    flat = np.where(np.isnan(flat), np.inf, flat)  # a lost point reads alike in both copies
    _, first, inverse = np.unique(flat, axis=0, return_index=True, return_inverse=True)
    inverse = np.ravel(inverse)
    dup = np.flatnonzero(first[inverse] != np.arange(K))
    if not len(dup):
        return ()
    pairs = ", ".join(f"{int(rows[i])} (row {int(rows[first[inverse[i]]])})" for i in dup[:10])
    more = f" and {len(dup) - 10} more" if len(dup) > 10 else ""
    return (
        f"row(s) {pairs}{more} repeat the row named beside them to the last digit, joints and measurements: a "
        "row written twice? A measurement of the same posture again would differ by its noise. Each copy weighs "
        "in the fit as a measurement of its own",
    )
