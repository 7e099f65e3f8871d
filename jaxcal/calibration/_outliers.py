r"""Gross outliers: found, named and kept out of the model.

A pose is an **outlier** when its residual is far beyond the noise of the others. After a fit,
each pose's residual is standardised by robust noise scales, one for the position rows and one
for the rotation rows (:func:`jaxcal.solvers.robust_scale`: the median of the poses' norms over
the chi median of their rows, unaffected by up to half the poses being outliers):
``u_k^2 = |e_pos,k|^2 / s_pos^2 + |e_rot,k|^2 / s_rot^2``, the pose's residual in standard
deviations of the noise per coordinate. A pose is
flagged when ``u_k`` exceeds :func:`jaxcal.solvers.outlier_threshold` of its observed rows:
as improbable under Gaussian noise as a one-sided ``outlier_sigmas``-sigma normal deviation (5:
2.9e-7 per pose, threshold 5.77 for a position, 6.40 for a pose, 7.34 for four points).

**Detection** (:func:`detect`), per fit (every data set, training set and candidate is a member
of one compiled solve; a pose's weight is data, so nothing is compiled again):

1. the fit as given; no pose beyond the threshold: done, the fit is unchanged;
2. else a few Cauchy-reweighted refits (pose weights ``1 / (1 + (u/c)^2)``, warm-started), so
   that the outliers no longer pull the model and hide among the clean poses' residuals;
3. the poses beyond the threshold are excluded (weight 0) and the plain fit repeated, until the
   excluded set is stable (the scales stay medians over every pose: they need no trimming, and
   trimming them would flag ever more poses of data whose residuals have heavy tails).

The caller then refits its whole pipeline without the excluded poses. More than
``max_outlier_fraction`` of the poses flagged is not a few bad measurements but a data set that
does not fit the model: :func:`too_many` says so, and the fit is refused.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable

import numpy as np
from jaxtyping import Bool, Float

from ..model import observed
from ..solvers import outlier_threshold, robust_scale, robust_weights
from ._checks import zero_points

ROBUST_ROUNDS = 3
"""Cauchy-reweighted refits before the first exclusion."""
MAX_ROUNDS = 5
"""Most exclusion rounds (each a refit) before the excluded set is taken as it is."""
REWEIGHT_SHARE = 0.5
"""The detector is fitted with the frames-only residual as its noise weights. Where the robot's
own errors make most of that residual (a simulated or laser-tracked arm whose nominal model is
millimetres off, measured to hundredths), the prior holds the detector's parameters more than
the data would, and the noise it finds stays far above the measurements': outliers of a few
millimetres pass. When the noise found is below this share of the weights,
:func:`jaxcal.calibrate_data` detects again with that noise as the weights, and keeps the new
detection only if its noise falls below this share again (the prior was what held the fit; on
real arms whose residual is not geometric it barely moves, and the first detection stands); then
again while the noise keeps falling below :data:`REFINE_SHARE` of the last (a detector halfway
down still flags clean poses whose residual is its own misfit); at most :data:`REWEIGHTS` times."""
REFINE_SHARE = 0.8
REWEIGHTS = 4
UNMASK_SHARE = 0.5
"""When no pose stands out of a least-squares fit, the detection looks again with robust weights
(:func:`detect`, ``unmask``) and goes on only if the noise they find is below this share of the
first: outliers had pulled the fit (a lost marker written as 0, 0, 0 in a tenth of the rows of a
tracker metres away). Otherwise the first fit stands: excluding a pose raises its own residual,
and on clean data with few poses per parameter that alone would flag some."""
UNMASK_PROBE = 0.8
"""... and the first robust refit must bring it below this share, or the looking stops there (on
clean data the robust noise barely moves: one refit, not all of them)."""
REDETECT_SIGMA = 0.5
"""When leaving the outliers out brings the frames-only noise below this share of what it was,
gross outliers (a lost marker written as 0, 0, 0; swapped labels) set the weights and pulled the
reference the detection ran with: the caller detects again over every pose from the fit without
them (without the :data:`GROSS` ones alone, when those account for the drop)."""
GROSS = 10.0
"""Flagged poses beyond this many times their threshold are gross (hundreds of sigmas: a marker
read as 0, 0, 0), the others a pose or two the arm or the tracker missed by a few sigmas. The
detection again starts from the fit without the gross ones alone where leaving them out is what
more than halves the noise: the outliers of the file without the gross rows, not those of a
detection the gross rows pulled (which can take a clean pose for an outlier and keep one)."""


def gross(det: "Detection") -> np.ndarray:
    """``(B, K)`` the flagged poses of ``det`` beyond :data:`GROSS` times their threshold."""
    return det.flags & (det.sigmas > GROSS * det.threshold)


@dataclasses.dataclass(frozen=True, eq=False)
class Detection:
    """Outliers of a batch of fits (leading axis: members)."""

    flags: Bool[np.ndarray, "B K"]
    """Poses found to be outliers: excluded from :attr:`fit` (unless detection was off)."""
    sigmas: Float[np.ndarray, "B K"]
    """Every pose's standardised residual ``u_k`` under :attr:`fit` (units of :attr:`scale`)."""
    scale: Float[np.ndarray, "B 2"]
    """The robust noise scale per position and per rotation row (units of the fit's sigmas)."""
    threshold: Float[np.ndarray, "B K"]
    """Each pose's threshold on :attr:`sigmas`."""
    fit: dict
    """The fits (:func:`jaxcal.calibration._core.run_members`'s output) without the outliers."""
    rounds: int = 0
    """Refits done (0: nothing was flagged)."""
    noise: Float[np.ndarray, "B 2"] | None = None
    """:attr:`scale` in mm and rad: the robust noise the threshold was measured in (set by the
    caller that knows the fit's sigmas)."""


def standardised(fit: dict, dof_pos, weights, *, poses: bool, loss_scale=None) -> tuple[np.ndarray, np.ndarray]:
    """``(u (B, K), scale (B, 2))``: each pose's residual in units of the noise per row,
    ``u^2 = |W e_pos|^2 / s_pos^2 + |W e_rot|^2 / s_rot^2``, the scales robust estimates over the
    poses with positive ``weights`` (:func:`jaxcal.solvers.robust_scale`), one for the position
    rows (``dof_pos`` of them per pose) and one for the rotation rows (``poses``), or the given
    ``loss_scale``. Each its own: a fit's weights come from the frames-only residual, not the
    noise, and a norm over rows of unequal variance would have heavier tails than chi."""
    pn, rn = (np.atleast_2d(np.asarray(fit[k], float)) for k in ("pos_norms", "rot_norms"))
    weights = np.asarray(weights, float)
    if loss_scale is not None:
        scale = np.full((len(pn), 2), float(loss_scale))
    else:
        sr = np.asarray(robust_scale(rn, 3, weights)) if poses else np.ones(len(pn))
        scale = np.stack([np.asarray(robust_scale(pn, dof_pos, weights)), sr], -1).reshape(-1, 2)
    u2 = (pn / scale[:, :1]) ** 2 + ((rn / scale[:, 1:]) ** 2 if poses else 0.0)
    return np.sqrt(u2), scale


def position_rows(target) -> np.ndarray:
    """Each pose's observed position rows (any leading axes): 3 per point seen, 3 for a pose."""
    seen = observed(np.asarray(target))
    return seen[..., :3].sum(-1) if np.shape(target)[-2:] == (4, 4) else seen.sum(-1)


def false_alarm(sigmas: float) -> float:
    """Probability that a clean pose is flagged at the level ``sigmas``: the one-sided normal tail."""
    return 0.5 * math.erfc(sigmas / math.sqrt(2.0))


def thresholds(dof, sigmas: float) -> np.ndarray:
    """:func:`jaxcal.solvers.outlier_threshold` of each pose's row count ``dof``."""
    dof = np.asarray(dof, int)
    values = {int(d): outlier_threshold(int(d), sigmas) for d in np.unique(dof)}
    return np.vectorize(values.__getitem__, otypes=[float])(dof)


def detect(
    refit: Callable[[np.ndarray, np.ndarray], dict],
    fit: dict,
    masks,
    dof_pos,
    *,
    poses: bool,
    sigmas: float,
    loss_scale=None,
    robust_rounds: int = ROBUST_ROUNDS,
    max_rounds: int = MAX_ROUNDS,
    unmask: bool = False,
) -> Detection:
    """Find the outliers of every member of ``fit`` (module docstring).

    **Arguments**: ``refit(pose_weights (B, K), x0 (B, m))`` fits every member again with these
    pose weights from ``x0`` and returns what ``fit`` is (:func:`._core.run_members`'s output:
    ``pos_norms``, ``rot_norms``, ``x``, ...); ``fit`` the members' fits on ``masks (B, K)``
    (their poses); ``dof_pos`` ``(K,)`` or ``(B, K)`` each pose's observed position rows;
    ``poses`` whether rotations are measured; ``sigmas`` the outlier level
    (:func:`jaxcal.solvers.outlier_threshold`); ``loss_scale`` a given noise scale per row;
    ``unmask``: when no pose stands out, the robust refits are made anyway (one data set's
    detection: outliers that pulled the fit until none stands out are found).

    **Returns** a :class:`Detection`; members with nothing flagged keep their fit unchanged.
    """
    masks = np.asarray(masks, bool)
    dof_pos = np.broadcast_to(np.asarray(dof_pos, int), masks.shape)
    dof = dof_pos + 3 * poses
    thr = thresholds(dof, sigmas)
    kw = dict(poses=poses, loss_scale=loss_scale)
    u, scale = standardised(fit, dof_pos, masks, **kw)
    flags = masks & (u > thr)
    todo = flags.any(-1, keepdims=True)
    first = Detection(flags, u, scale, thr, fit)
    if not todo.any():
        if not unmask:
            return first
        # a gross minority can pull a least-squares fit until no pose stands out (masking): look
        # again with the robust weights; nothing flagged then, and the fit stands as it was
        todo = np.ones_like(todo)
    for r in range(robust_rounds):  # members with nothing flagged refit as they were (warm: no step)
        c = np.asarray(robust_weights(u, 1.0, dof, "cauchy"))
        fit = refit(np.where(todo, masks * c, masks), fit["x"])
        u, scale = standardised(fit, dof_pos, masks, **kw)
        if r == 0 and not first.flags.any():  # looking again: masking shows as a noise the robust fit shrinks
            todo &= scale[:, :1] < UNMASK_PROBE * first.scale[:, :1]
            if not todo.any():
                return first
    if not first.flags.any():
        todo &= scale[:, :1] < UNMASK_SHARE * first.scale[:, :1]
    used = masks & (u > thr) & todo
    if not used.any() and not first.flags.any():
        return first
    for r in range(max_rounds):  # the scale over every pose: the median needs no trimming
        fit = refit((masks & ~used).astype(float), fit["x"])
        u, scale = standardised(fit, dof_pos, masks, **kw)
        new = masks & (u > thr) & todo
        if np.array_equal(new, used) or r == max_rounds - 1:  # the fit excludes `used`: that set
            break
        used = new
    return Detection(used, u, scale, thr, fit, robust_rounds + r + 1)


def assess(fit: dict, masks, dof_pos, *, poses: bool, sigmas: float, loss_scale=None, excluded=None) -> Detection:
    """The :class:`Detection` of fits as they are: the ``excluded`` poses are the flags; without
    ``excluded`` (detection off) the poses beyond the threshold are, though the fit kept them."""
    masks = np.asarray(masks, bool)
    dof_pos = np.broadcast_to(np.asarray(dof_pos, int), masks.shape)
    u, scale = standardised(fit, dof_pos, masks, poses=poses, loss_scale=loss_scale)
    thr = thresholds(dof_pos + 3 * poses, sigmas)
    flags = masks & (u > thr) if excluded is None else np.asarray(excluded, bool)
    return Detection(flags, u, scale, thr, fit)


def judged(fit: dict, target, n_points: int, opts, excluded=None) -> Detection:
    """The poses of one fit of every pose (``fit`` with a leading member axis of 1) as the rule
    judges them, in the robust noise of all of them: what the report lists, and what the workflow's
    second look goes by (``excluded``: the poses left out, as :func:`assess`)."""
    K = np.shape(fit["pos_norms"])[-1]
    return assess(
        fit, np.ones((1, K), bool), position_rows(target), poses=n_points == 0, sigmas=opts.outlier_sigmas,
        loss_scale=opts.loss_scale, excluded=excluded,
    )  # fmt: skip


def too_many(flags, sigmas, position_mm, rows, limit: float, *, worst: int = 5, rotation_deg=None) -> str:
    """Empty when at most ``limit`` (a fraction) of the poses are outliers; else what a refusal
    says: how many, the limit, and the ``worst`` rows (file row, position error mm, rotation
    error deg where given, sigmas)."""
    flags = np.asarray(flags, bool)
    n, K = int(flags.sum()), flags.size
    if n <= limit * K:
        return ""
    idx = np.flatnonzero(flags)
    idx = idx[np.argsort(-np.asarray(sigmas)[idx])][:worst]
    deg = (lambda k: "") if rotation_deg is None else (lambda k: f", {rotation_deg[k]:.3g} deg")  # noqa: E731
    listed = ", ".join(f"{int(rows[k])} ({position_mm[k]:.3g} mm{deg(k)}, {sigmas[k]:.3g} sigma)" for k in idx)
    return (
        f"{n} of {K} poses ({100 * n / K:.0f} %) are outliers, more than max_outlier_fraction "
        f"{100 * limit:.0f} %: not a few bad measurements but data the model does not fit; worst rows: {listed}"
    )


REGION_CHANCE = 0.002
"""Outliers that lie together at one end of a joint's range (or at both ends) are taken as a
region of the arm's motion where it errs (a sag, a cable, a joint stop; or a measurement fault
there, such as the tracker's line of sight) when scattered gross errors would lie so with at most
this probability (Bonferroni over every joint and end; the cut-offs scanned add a little)."""
REGION_MIN = 3
"""Fewest outliers that make a region: two together at an end are chance too often."""
HINT_CHANCE = 0.05
"""Outliers that lie together at an end with a chance below this, but too few (two) or in too
few poses to make a region, are pointed out in a note: the figures leave them out."""


@dataclasses.dataclass(frozen=True, eq=False)
class Region:
    """Outliers together in one part of a joint's range (:func:`region`)."""

    joint: int
    end: str
    """``"high"``: ``q >= bound``; ``"low"``: ``q <= bound``; ``"both"``: ``|q - centre| >= bound``."""
    bound: float
    centre: float
    flags: Bool[np.ndarray, " K"]
    """The outliers in the region."""
    poses: int
    """Poses of the data in the region, outliers or not."""
    chance: float
    """Probability that scattered outliers lie so (Bonferroni over joints and ends)."""


def region(
    q: Float[np.ndarray, "K n"],
    flags: Bool[np.ndarray, " K"],
    *,
    chance: float = REGION_CHANCE,
    least: int = REGION_MIN,
) -> Region | None:
    """The part of one joint's range (one end, or both ends about its middle) where at least
    ``least`` outliers lie together beyond ``chance``, or ``None``. Each joint's poses are ranked by
    how far they lie towards an end; the chance that at least ``f`` of the ``n`` outliers fall
    among the ``m`` poses farthest out, were they ``n`` poses drawn at random, is hypergeometric.
    Every outlier's place sets a cut-off ``m``; the least chance wins."""
    q, flags = np.asarray(q, float), np.asarray(flags, bool)
    K, n = len(flags), int(flags.sum())
    if n < least:
        return None
    from scipy.stats import hypergeom  # only where outliers were found: no import cost otherwise

    tests = 3 * q.shape[1]
    best = None
    for j in range(q.shape[1]):
        centre = 0.5 * (q[:, j].min() + q[:, j].max())
        for end, s in (("high", q[:, j]), ("low", -q[:, j]), ("both", np.abs(q[:, j] - centre))):
            for cut in np.unique(s[flags]):
                inside = s >= cut
                f = int((inside & flags).sum())
                if f < least:
                    continue
                odds = min(1.0, tests * float(hypergeom.sf(f - 1, K, n, int(inside.sum()))))
                if best is None or odds < best.chance:
                    bound = float(-cut if end == "low" else cut)
                    best = Region(j, end, bound, float(centre), inside & flags, int(inside.sum()), odds)
    return best if best is not None and best.chance <= chance else None


def not_rigid(predicted, target, flags, sigmas: float) -> Bool[np.ndarray, " K"]:
    """The flagged poses whose measured points do not move as one rigid body. An error of the arm
    moves every point on the tool together; a marker that slipped, was taken for another or was
    seen through a reflection moves alone: a measurement fault, not a region of the arm's motion
    (:func:`region`). Each pose's predicted points ``(K, M, 3)`` are moved onto the points seen
    by the best rigid motion (Kabsch); the residual, ``3 m - 6`` rows for ``m`` points seen, is
    standardised by its robust scale over the poses not flagged (the noise: the tool's points keep
    their shape, whatever the arm's error), and a flagged pose beyond the outlier threshold of its
    rows is named. Fewer than three points seen: never."""
    P, T = np.asarray(predicted, float), np.asarray(target, float)
    flags = np.asarray(flags, bool)
    seen = np.all(np.isfinite(T), -1) & np.all(np.isfinite(P), -1)  # (K, M)
    m = seen.sum(-1)
    ok = m >= 3
    if P.ndim != 3 or not (ok & flags).any() or not (ok & ~flags).any():
        return np.zeros(len(flags), bool)
    w = seen[..., None].astype(float)
    Pz, Tz = np.where(seen[..., None], P, 0.0), np.where(seen[..., None], T, 0.0)
    n = np.maximum(m, 1)[:, None, None]
    cp, ct = (Pz * w).sum(1, keepdims=True) / n, (Tz * w).sum(1, keepdims=True) / n
    A, B = (Pz - cp) * w, (Tz - ct) * w
    U, _, Vt = np.linalg.svd(np.swapaxes(A, 1, 2) @ B)  # (K, 3, 3): A^T B
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.broadcast_to(np.eye(3), U.shape).copy()
    D[:, 2, 2] = d
    R = U @ D @ Vt  # rows of A times R fit rows of B
    left = np.sqrt((((A @ R - B) * w) ** 2).sum((1, 2)))
    dof = np.where(ok, 3 * m - 6, 1)
    scale = float(robust_scale(np.where(ok, left, 0.0), dof, (ok & ~flags).astype(float)))
    return flags & ok & (left / scale > thresholds(dof, sigmas))


SWAP_FIT = 5.0
"""A flagged pose fits once its points are relabelled when its RMS point error drops to this
many times the noise, and to a fifth of what it was, or less."""
SWAP_ALL_BELOW = 6
"""With fewer points than this every relabelling is tried (119 for five points); with more,
exchanges of two points only."""


def _relabellings(M: int) -> list[tuple[int, ...]]:
    """The relabellings tried: ``perm[k]`` is the file's column that holds point ``k``."""
    if M < SWAP_ALL_BELOW:
        return [p for p in itertools.permutations(range(M)) if p != tuple(range(M))]
    out = []
    for i, j in itertools.combinations(range(M), 2):
        p = list(range(M))
        p[i], p[j] = j, i
        out.append(tuple(p))
    return out


def _cycles(perm, nums) -> str:
    """``points 3 and 4`` for an exchange, ``points 1, 2 and 3 rotated`` for a longer cycle."""
    seen, parts = set(), []
    for k in range(len(perm)):
        if k in seen or perm[k] == k:
            continue
        c, j = [], k
        while j not in seen:
            seen.add(j)
            c.append(int(nums[j]))
            j = perm[j]
        c = sorted(c)
        names = ", ".join(map(str, c[:-1])) + f" and {c[-1]}"
        parts.append(f"points {names}" + (" rotated" if len(c) > 2 else ""))
    return "; ".join(parts)


ONE_POINT_SHARE = 0.9
"""The share of the flagged poses of several points whose worst point must be one and the same
for :func:`one_point_note` to name it."""


def one_point_note(pos_err, flags, rows, point_numbers=()) -> str:
    """What to say when one point is the worst of nearly every flagged pose (``pos_err (K, M)``
    mm, :data:`ONE_POINT_SHARE`): a marker that slipped on the tool (every pose from one on) or was
    taken for another, which leaving that point out mends. Empty otherwise."""
    e, idx = np.asarray(pos_err, float), np.flatnonzero(np.asarray(flags, bool))
    if e.ndim != 2 or e.shape[1] < 2 or not idx.size:
        return ""
    nums = list(point_numbers) or list(range(1, e.shape[1] + 1))
    worst = np.argmax(np.nan_to_num(e[idx], nan=-1.0), axis=1)
    j = int(np.bincount(worst, minlength=e.shape[1]).argmax())
    if np.mean(worst == j) < ONE_POINT_SHARE:
        return ""
    r = np.asarray(rows)[idx]
    span = f" (rows {r.min()} to {r.max()}, every row between)" if r.max() - r.min() + 1 == len(r) > 2 else ""
    others = ",".join(str(n) for k, n in enumerate(nums) if k != j)
    return (
        f"; point {nums[j]} is the worst point of {int(np.sum(worst == j))} of the {len(idx)} outliers{span}: a "
        f"marker that slipped on the tool or was taken for another? --points {others} leaves it out"
    )


def swaps_note(predicted, target, flags, noise_mm: float, rows, point_numbers=()) -> str:
    """The cause to name when most flagged poses of several points fit once their points are
    relabelled (two exchanged, or a few rotated; ``predicted``, ``target`` ``(K, M, 3)``):
    marker labels the tracker swapped, which no model fits and which relabelling in the file
    mends. Points are named by their numbers in the file (``point_numbers``, else 1..M), the
    columns the user relabels."""
    pred, meas = np.asarray(predicted, float), np.asarray(target, float)
    idx = np.flatnonzero(np.asarray(flags, bool))
    if meas.ndim != 3 or meas.shape[1] < 2 or not idx.size:
        return ""

    def rms(m):
        with np.errstate(invalid="ignore"):
            return np.sqrt(np.nanmean(np.sum((m - pred[idx]) ** 2, -1), -1))

    perms = _relabellings(meas.shape[1])
    now, best, which = rms(meas[idx]), np.full(idx.size, np.inf), np.zeros(idx.size, int)
    for n, perm in enumerate(perms):
        e = rms(meas[idx][:, list(perm)])
        better = e < best
        best[better], which[better] = e[better], n
    fits = (best <= SWAP_FIT * noise_mm) & (best <= now / 5)
    if fits.sum() * 2 <= idx.size:
        return ""
    nums = list(point_numbers) or list(range(1, meas.shape[1] + 1))
    used = [perms[n] for n in sorted(set(which[fits].tolist()))]
    found = sorted({c for p in used for c in _cycles(p, nums).split("; ")})  # one name per cycle
    exchanged = all(sum(a != b for a, b in enumerate(p)) == 2 for p in used)
    how = "two points are exchanged" if exchanged else "their points are relabelled"
    listed = ", ".join(str(int(rows[k])) for k in idx[fits][:8]) + (", ..." if fits.sum() > 8 else "")
    # every point moved along one cycle is also what a tool turned by a symmetry of the layout does
    turned = any(len(p) > 2 and all(p[k] != k for k in range(len(p))) for p in used)
    return (
        f"marker labels swapped: {int(fits.sum())} of the {idx.size} outlying poses fit once {how} "
        f"({'; '.join(found)}; rows {listed}). Correct the labels in the file"
        + (
            " (or, with markers placed symmetrically on the tool, look for a tool turned in those rows)"
            if turned
            else ""
        )
    )


def zeros_note(target, n_points: int, flags, point_numbers=()) -> str:
    """What to say when flagged poses measure a point at exactly 0, 0, 0: a lost marker that the
    export wrote as zeros (empty cells leave that point out and keep the pose's others). Points
    are named by their numbers in the file (``point_numbers``, else 1..M)."""
    zero = zero_points(target, n_points) & np.asarray(flags, bool)[:, None]  # (K, M)
    if not zero.any():
        return ""
    nums = list(point_numbers) or list(range(1, zero.shape[1] + 1))
    per = ", ".join(
        f"point {nums[j]} in {int(zero[:, j].sum())} of them" for j in range(zero.shape[1]) if zero[:, j].any()
    )
    return (
        f"; the outliers include positions at exactly 0, 0, 0 ({per}): lost markers written as zeros? "
        "Export them as empty cells: that point is then left out and the pose's other points kept"
    )


def pose_position_mm(pos_err) -> np.ndarray:
    """Each pose's position error (mm): the point's, or the RMS over the points seen."""
    pos_err = np.asarray(pos_err, float)
    if pos_err.ndim == 1:
        return pos_err
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.nanmean(pos_err**2, -1))


def describe(
    det: Detection, member: int, pos_err, rot_err_deg, rows, *, excluded: bool, point_numbers=()
) -> list[dict]:
    """JSON entries of the flagged poses of one member, worst first: ``row`` (the file's),
    ``position_mm``, ``rotation_deg`` (poses), ``sigmas``, ``threshold_sigmas``, ``excluded``;
    with several points, ``worst_point`` (its number in the file, ``point_numbers``, else 1..M)
    and ``worst_point_mm``: the marker to look at (``position_mm`` is the RMS over the points)."""
    f, u, t = det.flags[member], det.sigmas[member], det.threshold[member]
    pos = pose_position_mm(pos_err)
    per_point = np.asarray(pos_err, float)
    numbers = (list(point_numbers) or list(range(1, per_point.shape[-1] + 1))) if per_point.ndim > 1 else []
    out = []
    for k in np.flatnonzero(f)[np.argsort(-u[f])]:
        e = {"row": int(rows[k]), "position_mm": float(pos[k])}
        if len(numbers) > 1:
            j = int(np.nanargmax(per_point[k]))
            e |= {"worst_point": int(numbers[j]), "worst_point_mm": float(per_point[k, j])}
        if rot_err_deg is not None:
            e["rotation_deg"] = float(rot_err_deg[k])
        e |= {"sigmas": float(u[k]), "threshold_sigmas": float(t[k]), "excluded": excluded}
        out.append(e)
    return out


def found(fit: dict, refit, masks, target, opts, *, unmask: bool = False) -> Detection:
    """The outliers of the fits ``fit`` on ``masks`` as the options ask (``keep_outliers``: the
    poses beyond the threshold, kept in the fit; else :func:`detect`, ``refit`` as there), for
    the measurements ``target``."""
    kw = dict(poses=np.shape(target)[-2:] == (4, 4), sigmas=opts.outlier_sigmas, loss_scale=opts.loss_scale)
    dof = position_rows(target)
    if opts.keep_outliers:
        return assess(fit, masks, dof, **kw)
    return detect(refit, fit, masks, dof, unmask=unmask, **kw)
