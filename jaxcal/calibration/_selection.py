r"""Model selection: which parameters to estimate, under which prior, scored by how well a model
predicts postures it was not fitted on, inside and beyond the training ranges.

## The linearised problem
Around a reference model (the frames-only fit of all poses) a calibration is linear to second
order in its parameters: a pose's weighted residual is ``e_k(x) = r_k - J_k x``. A candidate
model, free parameters ``F`` and prior weights ``p`` (:meth:`Candidate.prior_weight`), fitted on a training
set ``T`` solves

$$\Big(\sum_{k \in T} J_k^\top J_k + \mathrm{diag}(p^2)\Big)_{FF}\, x_F = \Big(\sum_{k \in T} J_k^\top r_k\Big)_F,$$

summed over each training set once for all candidates. Thousands of such fits (every candidate on
every training set, inside every outer fold) are small linear solves, and only the chosen model
is fitted in full (:mod:`._core`).

## The scoring rule
Within one session, K-fold cross-validation asks how well a model predicts *new postures among
the old ones*. A model that is used tomorrow also meets postures beyond the training ranges,
where a parameter fitted to noise does most harm. The score of a candidate is therefore

$$S = \sqrt{\tfrac12\,\mathrm{MSE}_{\text{K-fold}} + \tfrac12\,\mathrm{MSE}_{\text{ends}}},$$

the mean squared held-out position error (mm², every point of every held-out pose) of seeded
K-fold folds and of **range-end folds**: for every joint that moves, the poses with its lowest
:data:`END_FRACTION` of values held out together, and those with its highest. Each range-end fold
is fitted on a training set whose range of that joint stops short of the held-out poses: its
error is an extrapolation error.

## Physically scaled priors
A prior (ridge) of standard deviation ``s`` mm holds each parameter ``x_j`` with weight
``p_j = L_j / s``, ``L_j`` its **lever**: the RMS displacement of the measured points per unit
``x_j`` over the data (:func:`lever`). A length has ``L = 1``; an angle, the RMS distance of the
points from the axis it turns about. So ``s`` says how far (mm) each parameter is expected to move
the points, whatever its unit: 1 mm and the angle that moves the points 1 mm weigh the same.

## Choosing
The candidate chosen is the simplest (fewest free parameters, then the strongest prior; rigid
before compliant) whose score is within one standard error of the lowest: the "one standard
error" rule of cross-validation, since a lower score by less than its own noise is no evidence.

## Parameter-level selection
The chosen candidate's parameters are then pruned one at a time, the least significant first
(smallest ``|x_j| / se_j`` of the fit on all poses), down to none. How many to drop is itself
chosen by the held-out folds, each of which drops *its own* least significant parameters, ordered
by a fit on its training poses alone: the score of dropping ``n`` is that of the folds' models
with ``n`` dropped. (Scored along the order of all the poses, a fold's held-out poses would have
helped decide which parameters its model keeps, and the score would favour pruning more than the
data support.) The sparsest whose score is within :data:`PRUNE_SE` standard errors, and
:data:`PRUNE_TOLERANCE`, of the best is kept: what remains are the parameters the data support.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from jaxtyping import Bool, Float

END_FRACTION = 0.15
"""Share of the poses at each end of a joint's range that a range-end fold holds out."""
PRUNE_TOLERANCE = 0.01
"""Pruning keeps the sparsest model whose score is within :data:`PRUNE_SE` standard errors of the
best, and at least within this fraction of it."""
SIMPLER_TOLERANCE = 0.01
"""A simpler candidate whose score is within one standard error of the best, and at least within
this fraction of it, wins."""
PRUNE_SE = 0.0
"""Pruning keeps the sparsest model within this many standard errors of the best number dropped
(and :data:`PRUNE_TOLERANCE`): the folds' own orders already make a dropped parameter's cost
honest, and pseudo-sessions of real data and later sessions of a simulated arm support no more
(docs/selection.md)."""
MAX_CONDITION = 1e6
"""A candidate whose column-scaled, weighted Jacobian (prior rows included) is worse conditioned
than this fails: its parameters are not separable on these poses, and its full fit's normal
equations (condition number squared) would be rounding error."""


def failure(condition: float) -> str:
    """Why a candidate failed (a non-finite score): its parameters are not separable on these
    poses, or else its held-out fits did not give finite errors."""
    if condition >= MAX_CONDITION or not np.isfinite(condition):
        return (
            f"its parameters are not separable on these poses: condition number {condition:.3g} of its "
            f"column-scaled equations, above {MAX_CONDITION:.0e} (a fit would be singular)"
        )
    return "its held-out fits gave non-finite errors"


@dataclasses.dataclass(frozen=True, eq=False)
class Linear:
    """The calibration problem linearised at a reference (module docstring)."""

    J: Float[np.ndarray, "K rows m"]
    """Weighted Jacobian of the residual rows (0 where a row is not observed)."""
    r: Float[np.ndarray, "K rows"]
    """Weighted residual at the reference (0 where not observed)."""
    seen: Bool[np.ndarray, "K rows"]
    pos_scale: Float[np.ndarray, " rows"]
    """mm per weighted unit of each position row; 0 for rotation rows."""
    n_points: int
    blocks: np.ndarray | None = None
    """``(K, m m)`` each pose's ``J_k^T J_k``, formed by the first :func:`sums` (small problems)."""

    @property
    def K(self) -> int:
        return self.J.shape[0]

    @property
    def m(self) -> int:
        return self.J.shape[-1]


def linearise(J, r, weights, n_points: int) -> Linear:
    """:class:`Linear` from the Jacobian ``J (K, rows, m)`` of the predicted measurements and the
    residual ``r (K, rows)`` (measured - predicted; NaN where a point was lost) at the reference,
    mm and rad, and the row weights ``1 / sigma`` ``(rows,)``."""
    J, r, w = np.asarray(J, float), np.asarray(r, float), np.asarray(weights, float)
    seen = np.isfinite(r)
    Jw = np.where(seen[..., None], J * w[None, :, None], 0.0)
    rw = np.where(seen, r * w[None], 0.0)
    rows = r.shape[1]
    pos = np.arange(rows) < (3 if n_points == 0 else rows)
    scale = np.where(pos, 1.0 / w, 0.0)
    return Linear(Jw, rw, seen, scale, n_points)


BLOCKS_MAX = 2**24
"""Largest number of entries of the per-pose normal blocks kept in memory (:func:`sums`)."""


def sums(lin: Linear, train) -> tuple[np.ndarray, np.ndarray]:
    """``(sum_k w_fk J_k^T J_k (F, m, m), sum_k w_fk J_k^T r_k (F, m))`` of the pose weights
    ``train (F, K)``: a product with the per-pose blocks where they fit in memory."""
    train = np.atleast_2d(np.asarray(train, float))
    K, m = lin.K, lin.m
    b = np.einsum("fk,kri,kr->fi", train, lin.J, lin.r, optimize=True)
    if K * m * m > BLOCKS_MAX:
        return np.einsum("fk,kri,krj->fij", train, lin.J, lin.J, optimize=True), b
    if lin.blocks is None:  # formed once per linearisation
        object.__setattr__(lin, "blocks", np.einsum("kri,krj->kij", lin.J, lin.J).reshape(K, m * m))
    return (train @ lin.blocks).reshape(-1, m, m), b


def lever(J, n_points: int) -> Float[np.ndarray, " m"]:
    """RMS displacement (mm) of the measured points per unit of each parameter over the poses
    (``J (K, rows, m)`` unweighted: the position rows of each point, or a pose's first three)."""
    J = np.asarray(J, float)
    M = max(n_points, 1)
    P = J[:, : 3 * M].reshape(J.shape[0], M, 3, -1)
    P = np.where(np.isfinite(P), P, 0.0)
    return np.sqrt(np.mean(np.sum(P**2, 2), axis=(0, 1)))


# -- folds ------------------------------------------------------------------------------------------


def grouped_folds(order, groups, k: int) -> np.ndarray:
    """Fold (0..k-1) of each pose, taken in ``order``: a pose joins its group's fold, or, the
    first of its group, the fold with the fewest poses so far (the lowest of equals). Repeats of a
    posture (``groups``, :func:`._core.posture_ids`) are then held out together: a twin left in
    the training set would score its own noise. Without repeats, pose ``order[j]`` is in fold
    ``j % k``."""
    groups = np.asarray(groups)
    fold = np.full(len(groups), -1, np.int64)
    size = np.zeros(k, np.int64)
    of_group: dict = {}
    for i in order:
        g = int(groups[i])
        if g not in of_group:
            of_group[g] = int(np.argmin(size))
        fold[i] = of_group[g]
        size[fold[i]] += 1
    return fold


def kfold_held(valid, k: int, seed: int, groups=None) -> Bool[np.ndarray, "k K"]:
    """``k`` held-out sets of a seeded permutation of the ``valid`` poses cut into nearly equal
    parts, the repeats of a posture (``groups``) in one (:func:`grouped_folds`)."""
    idx = np.flatnonzero(valid)
    g = np.arange(len(idx)) if groups is None else np.asarray(groups)[idx]
    k = min(k, len(np.unique(g)))  # no fold without a posture
    perm = np.random.default_rng(seed).permutation(len(idx))
    fold = grouped_folds(perm, g, k)
    out = np.zeros((k, len(valid)), bool)
    out[fold, idx] = True
    return out


def range_end_held(q, valid, fraction: float = END_FRACTION, groups=None) -> Bool[np.ndarray, "E K"]:
    """For every joint that moves over the ``valid`` poses, the poses among its lowest and among its
    highest ``fraction`` of values (at least one each), held out together, with the other
    repeats of their postures (``groups``)."""
    q = np.asarray(q, float)
    idx = np.flatnonzero(valid)
    n_end = max(1, int(round(fraction * len(idx))))
    out = []
    for j in range(q.shape[1]):
        v = q[idx, j]
        if np.ptp(v) <= 1e-9 * max(1.0, np.abs(v).max()):
            continue
        order = np.argsort(v, kind="stable")
        for end in (order[:n_end], order[-n_end:]):
            m = np.zeros(len(valid), bool)
            m[idx[end]] = True
            if groups is not None:
                m |= np.isin(groups, np.asarray(groups)[m]) & np.asarray(valid, bool)
            out.append(m)
    return np.array(out, bool).reshape(-1, len(valid))


@dataclasses.dataclass(frozen=True, eq=False)
class Rule:
    """The held-out sets of the scoring rule over some poses (K-fold and range-end folds), with the
    sums of their training sets and of all the poses (:func:`sums`), formed once for every
    candidate."""

    held: Bool[np.ndarray, "F K"]
    """K-fold sets first, then range-end sets."""
    n_kfold: int
    valid: Bool[np.ndarray, " K"]
    A: Float[np.ndarray, "F m m"]
    b: Float[np.ndarray, "F m"]
    A_all: Float[np.ndarray, "m m"]
    b_all: Float[np.ndarray, " m"]

    @classmethod
    def of(cls, lin: "Linear", q, valid, k: int, seed: int, groups=None) -> "Rule":
        valid = np.asarray(valid, bool)
        kfold = kfold_held(valid, k, seed, groups)
        held = np.concatenate([kfold, range_end_held(q, valid, groups=groups)]) & valid[None]
        A, b = sums(lin, np.concatenate([valid[None] & ~held, valid[None]]).astype(float))
        return cls(held, len(kfold), valid, A[:-1], b[:-1], A[-1], b[-1])


# -- fits and scores ----------------------------------------------------------------------------------


def solve(A, b, free, prior) -> Float[np.ndarray, "C F m"]:
    """Every candidate (``free (C, m)`` bool, ``prior (C, m)``) on every training set whose sums
    are ``A (F, m, m)``, ``b (F, m)``: ``x (C, F, m)``, 0 outside each free set."""
    free = np.atleast_2d(np.asarray(free, bool))
    prior = np.atleast_2d(np.asarray(prior, float))
    A, b = np.asarray(A)[None], np.asarray(b)[None]
    m = A.shape[-1]
    A = A + (np.eye(m) * prior[:, None, :] ** 2)[:, None]  # (C, F, m, m)
    F_ = free[:, None, :, None] & free[:, None, None, :]
    A = np.where(F_, A, 0.0) + np.eye(m) * (~free)[:, None, None, :]
    b = np.where(free[:, None, :], b, 0.0)
    x = _scaled_inverse(A) @ b[..., None]
    return np.where(free[:, None, :], x[..., 0], 0.0)


def fit(lin: Linear, train, free, prior) -> Float[np.ndarray, "C F m"]:
    """:func:`solve` on the training sets of pose weights ``train (F, K)``."""
    return solve(*sums(lin, train), free, prior)


def errors_mm(lin: Linear, x, poses) -> Float[np.ndarray, "C P M"]:
    """Position error norms (mm) of every point of the ``poses`` (indices) under each fit ``x (C,
    m)``; NaN for a lost point."""
    e = lin.r[poses][None] - np.einsum("krm,cm->ckr", lin.J[poses], x)
    M = max(lin.n_points, 1)
    pos = (e * lin.pos_scale)[..., : 3 * M].reshape(e.shape[:2] + (M, 3))
    seen = lin.seen[poses][:, : 3 * M].reshape(len(poses), M, 3).all(-1)
    return np.where(seen, np.linalg.norm(pos, axis=-1), np.nan)


def _squares(lin: Linear, rule: Rule, x, folds) -> list[np.ndarray]:
    """Squared held-out position errors (mm², lost points left out) of every candidate: one
    ``(C, n)`` array per fold."""
    out = []
    for f in folds:
        e = errors_mm(lin, x[:, f], np.flatnonzero(rule.held[f])).reshape(x.shape[0], -1)  # (C, P M)
        out.append(e[:, np.isfinite(e[0])] ** 2)
    return out


def _mse(lin: Linear, rule: Rule, x, folds) -> np.ndarray:
    sq = _squares(lin, rule, x, folds)
    return np.concatenate(sq, 1).mean(1) if sq and sum(a.shape[1] for a in sq) else np.full(x.shape[0], np.nan)


def score_error(lin: Linear, rule: Rule, free, prior) -> tuple[float, float]:
    """The score of one candidate and its standard error (mm): the spread of the held-out squared
    errors it averages, by the delta method."""
    x = solve(rule.A, rule.b, np.atleast_2d(free), np.atleast_2d(prior))
    F = rule.held.shape[0]
    parts = [_squares(lin, rule, x, r) for r in (range(rule.n_kfold), range(rule.n_kfold, F))]
    parts = [p for p in (np.concatenate(sq, 1)[0] for sq in parts if sq) if p.size]
    w = 1.0 / len(parts)
    ms = w * sum(p.mean() for p in parts)
    var = w**2 * sum(p.var(ddof=1) / p.size if p.size > 1 else 0.0 for p in parts)
    return float(np.sqrt(ms)), float(np.sqrt(var) / (2 * np.sqrt(ms))) if ms > 0 else 0.0


def score_parts(lin: Linear, rule: Rule, free, prior) -> tuple[np.ndarray, np.ndarray]:
    """``(K-fold, range-end)`` held-out RMS (mm) of each candidate; the second NaN without
    range-end folds."""
    x = solve(rule.A, rule.b, free, prior)  # (C, F, m)
    F = rule.held.shape[0]
    a = _mse(lin, rule, x, range(rule.n_kfold))
    b = _mse(lin, rule, x, range(rule.n_kfold, F)) if F > rule.n_kfold else np.full_like(a, np.nan)
    return np.sqrt(a), np.sqrt(b)


def score(lin: Linear, rule: Rule, free, prior) -> Float[np.ndarray, " C"]:
    """The scoring rule (module docstring) of each candidate, mm."""
    a, b = score_parts(lin, rule, free, prior)
    return np.where(np.isnan(b), a, np.sqrt(0.5 * a**2 + 0.5 * b**2))


def standard_errors(lin: Linear, rule: Rule, free, prior, x) -> Float[np.ndarray, " m"]:
    """Sandwich standard errors of the fit ``x (m,)`` of ``free`` on all the rule's poses:
    ``s^2 N^-1 J^T J N^-1``, ``s^2`` the weighted residual variance (0 outside ``free``)."""
    free = np.asarray(free, bool)
    JJ = rule.A_all[np.ix_(free, free)]
    Nf = JJ + np.diag(np.asarray(prior, float)[free] ** 2)
    Ni = _scaled_inverse(Nf)
    w = rule.valid.astype(float)
    e = lin.r - np.einsum("krm,m->kr", lin.J, x)
    dof = max(float(np.sum(w[:, None] * lin.seen)) - free.sum(), 1.0)
    s2 = float(np.sum(w[:, None] * e**2)) / dof
    out = np.zeros(lin.m)
    out[free] = np.sqrt(np.clip(np.diag(s2 * Ni @ JJ @ Ni), 0.0, None))
    return out


# -- selection ------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class Choice:
    """What :func:`select` chose."""

    index: int
    """The chosen candidate."""
    free: Bool[np.ndarray, " m"]
    """Its free parameters after pruning."""
    scores: Float[np.ndarray, " C"]
    """Every candidate's score (mm)."""
    parts: tuple
    """Every candidate's K-fold and range-end held-out RMS (mm), the two parts of its score."""
    conditions: Float[np.ndarray, " C"]
    """Condition number of every candidate's column-scaled normal equations on all the poses."""
    score: float
    """The pruned model's score (mm)."""
    pruned: tuple[tuple[int, float, float], ...] = ()
    """``(parameter, |x| / se, score)`` in the order they were dropped; the score is that of as many
    dropped, each held-out fold dropping its own (:func:`pruned_scores`)."""
    kept_t: dict = dataclasses.field(default_factory=dict)
    """``{parameter: |x| / se}`` of the kept prunable parameters in the final fit."""


def choose(scores, complexity, error: float = 0.0) -> int:
    """The simplest candidate (lowest ``complexity``, a sortable key per candidate) whose score is
    within ``error`` (the best score's standard error) and at least :data:`SIMPLER_TOLERANCE`
    of the lowest. A non-finite score never wins; -1 when every score is."""
    s = np.where(np.isfinite(scores), scores, np.inf)
    best = s.min()
    if not np.isfinite(best):
        return -1
    ok = [i for i in range(len(s)) if s[i] <= best + max(error, SIMPLER_TOLERANCE * best)]
    return min(ok, key=lambda i: complexity[i])


def prune(lin: Linear, rule: Rule, free, prior, prunable):
    """Drop the prunable parameters one at a time, the least significant first (smallest
    ``|x| / se`` of the fit on all the rule's poses), down to none; keep as many dropped as the
    held-out folds support (:func:`pruned_scores`): the sparsest within :data:`PRUNE_SE` standard
    errors (and at least :data:`PRUNE_TOLERANCE`) of the best. Returns ``(free, dropped,
    kept_t)``: ``dropped`` as :attr:`Choice.pruned`, ``kept_t`` the kept parameters' ``|x| / se``."""
    free = np.array(free, bool)
    prior = np.asarray(prior, float)
    prunable = np.asarray(prunable, bool)
    path, ts, order = [free], [], []
    while True:
        x = solve(rule.A_all[None], rule.b_all[None], free[None], prior[None])[0, 0]
        se = standard_errors(lin, rule, free, prior, x)
        t = {int(j): (abs(x[j]) / se[j] if se[j] > 0 else np.inf) for j in np.flatnonzero(free & prunable)}
        ts.append(t)
        if not t:
            break
        j = min(t, key=t.get)
        order.append((j, t[j]))
        free = free.copy()
        free[j] = False
        path.append(free)
    scores, errs = pruned_scores(lin, rule, path[0], prior, prunable, len(order))
    best = int(np.nanargmin(scores))
    limit = scores[best] + max(PRUNE_SE * errs[best], PRUNE_TOLERANCE * scores[best])
    k = max(i for i in range(len(path)) if scores[i] <= limit)
    return path[k], tuple((j, t, float(scores[i + 1])) for i, (j, t) in enumerate(order[:k])), ts[k]


def pruned_scores(lin: Linear, rule: Rule, free, prior, prunable, steps: int):
    """``(scores, errors)`` ``(steps + 1,)``: the score (mm, module docstring) of dropping ``n``
    parameters and its standard error, for ``n = 0..steps``. Every held-out fold drops the least
    significant of ``free``'s prunable parameters one at a time, by ``|x| / se`` of the fit on its
    own training poses (sandwich standard errors, as :func:`standard_errors`), and predicts its
    held-out poses after each; all folds at once, on ``free``'s parameters."""
    idx = np.flatnonzero(free)
    F, m, K = rule.held.shape[0], idx.size, lin.K
    A, b = rule.A[:, idx[:, None], idx[None, :]], rule.b[:, idx]
    J, pr, can = lin.J[..., idx].reshape(-1, m), np.asarray(prior, float)[idx], np.asarray(prunable, bool)[idx]
    train = (rule.valid[None] & ~rule.held).astype(float)  # (F, K)
    M = max(lin.n_points, 1)
    scored = (rule.held & rule.valid[None])[:, :, None] & lin.seen[:, : 3 * M].reshape(K, M, 3).all(-1)[None]
    rows = train @ lin.seen.sum(1).astype(float)
    keep = np.ones((F, m), bool)
    sq = []  # per number dropped: (F, K, M) squared held-out errors, NaN where not scored
    for n in range(steps + 1):
        both = keep[:, :, None] & keep[:, None, :]
        JJ = np.where(both, A, 0.0)
        N = JJ + np.eye(m) * np.where(keep, pr**2, 1.0)[:, None, :]
        Ni = _scaled_inverse(N)  # as solve's
        x = np.where(keep, (Ni @ np.where(keep, b, 0.0)[..., None])[..., 0], 0.0)
        e = lin.r[None] - (J @ x.T).T.reshape(F, K, -1)  # (F, K, rows), weighted
        pos = (e[..., : 3 * M] * lin.pos_scale[: 3 * M]).reshape(F, K, M, 3)
        sq.append(np.where(scored, np.sum(pos**2, -1), np.nan))
        if n == steps:
            break
        s2 = np.sum(train * np.sum(e**2, -1), 1) / np.maximum(rows - keep.sum(1), 1.0)
        var = np.sum((Ni @ JJ) * np.swapaxes(Ni, -1, -2), -1)  # the diagonal of N^-1 J^T J N^-1
        se = np.sqrt(np.clip(s2[:, None] * var, 0.0, None))
        # a parameter without a standard error goes last, but before any that cannot go
        t = np.where(se > 0, np.abs(x) / np.where(se > 0, se, 1.0), 1e300)
        t = np.where(keep & can, t, np.inf)
        some = (keep & can).any(1)
        keep = keep.copy()
        keep[np.flatnonzero(some), np.argmin(t, 1)[some]] = False
    kfold = np.arange(F) < rule.n_kfold
    scores, errs = np.zeros(steps + 1), np.zeros(steps + 1)
    for n, s in enumerate(sq):
        parts = [a[np.isfinite(a)] for a in (s[kfold], s[~kfold]) if np.isfinite(a).any()]
        w = 1.0 / len(parts)
        ms = w * sum(a.mean() for a in parts)
        var = w**2 * sum(a.var(ddof=1) / a.size if a.size > 1 else 0.0 for a in parts)
        scores[n], errs[n] = np.sqrt(ms), (np.sqrt(var) / (2 * np.sqrt(ms)) if ms > 0 else 0.0)
    return scores, errs


JITTER = 1e-12
"""Added to the column-scaled normal matrix's unit diagonal, so that a singular candidate still
gives finite numbers (:data:`MAX_CONDITION` fails it)."""


def _scaled_inverse(N):
    """The inverse of the normal matrices ``N (..., m, m)``, their columns scaled to a unit
    diagonal first: parameters in rad/mm (a compliance's column is the joint's lever times the
    gravity moment, ~1e5 mm per unit) sit beside mm, and a jitter or pivoting on the raw matrix
    would hold the small-columned parameters by the large ones' scale."""
    N = np.asarray(N, float)
    diag = np.diagonal(N, axis1=-2, axis2=-1)
    d = np.sqrt(np.where(diag > 0, diag, 1.0))
    S = N / d[..., :, None] / d[..., None, :] + JITTER * np.eye(N.shape[-1])
    try:
        Si = np.linalg.inv(S)
    except np.linalg.LinAlgError:
        Si = np.linalg.pinv(S)
    return Si / d[..., :, None] / d[..., None, :]


def condition(A, free) -> float:
    """Condition number of the normal matrix ``A`` of the ``free`` parameters, columns scaled."""
    N = np.asarray(A)[np.ix_(free, free)]
    if not N.size:  # nothing estimated (frames known, and the candidate estimates only them)
        return 1.0
    d = np.sqrt(np.clip(np.diag(N), 1e-300, None))
    ev = np.linalg.eigvalsh(N / np.outer(d, d))
    return float(np.sqrt(ev[-1] / ev[0])) if ev[0] > 0 else float("inf")


def select(lin: Linear, rule: Rule, free, prior, complexity, prunable) -> Choice:
    """Score every candidate (``free (C, m)``, ``prior (C, m)``), choose one (:func:`choose`) and
    prune it (:func:`prune`). ``index`` -1: every candidate failed (non-finite scores)."""
    free, prior = np.atleast_2d(free), np.atleast_2d(prior)
    a, b = score_parts(lin, rule, free, prior)
    scores = np.where(np.isnan(b), a, np.sqrt(0.5 * a**2 + 0.5 * b**2))
    conds = np.array([condition(rule.A_all + np.diag(p**2), f) for f, p in zip(free, prior)])
    scores = np.where(conds < MAX_CONDITION, scores, np.nan)
    c = choose(scores, complexity)
    if c >= 0:  # the one-standard-error rule: the simplest within the best's standard error
        c = choose(scores, complexity, score_error(lin, rule, free[c], prior[c])[1])
    if c < 0:
        return Choice(-1, free[0], scores, (a, b), conds, float("nan"))
    kept, dropped, t = prune(lin, rule, free[c], prior[c], prunable)
    final = dropped[-1][2] if dropped else float(scores[c])
    return Choice(c, kept, scores, (a, b), conds, final, dropped, t)
