"""What moved during the session: a measured point on the tool partway through the data (a
marker knocked or stuck on again), or the measurement frame along it (:func:`drift`: the
tracker's stand, the base, warming).

One fixed position per point spreads such a move over every pose, so no single pose stands out
as an outlier and the point's error, half the move on each side, can stay under the odd-point
note's threshold. What does stand out is a step in the point's residual taken in the tool's
frame, relative to the other points' residual there (an error of the arm's pose moves every
point nearly alike, a marker that moved moves alone), at the row where it moved. Rows are taken
in the file's order, the order they were measured in.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from jaxtyping import Bool, Float

MOVED_CHI2 = 30.0
"""The step's size, squared, in units of its own noise (3 degrees of freedom) above which a point
is said to have moved: chi-square's tail there is 1e-6, small next to the few hundred splits and
points tried on a file."""
MOVED_SHARE = 0.5
"""And the step explains more than this share of the point's relative residual: a drift of the
arm's own errors along the file is explained by no one step."""
MIN_SIDE = 4
"""Poses on each side of a step at the least."""


def moved_point(
    R: Float[np.ndarray, "K 3 3"],
    residual: Float[np.ndarray, "K M 3"],
    valid: Bool[np.ndarray, " K"],
    sigma_mm: float,
) -> tuple[int, int, int, np.ndarray, float] | None:
    """The point that moved on the tool, ``(point index, the last pose it was seen at before the
    move, the first after, the step in the tool frame (mm), its size in noise units)``, or None.
    ``R`` the tool's rotation at each pose, ``residual`` measured minus predicted in the
    measurement frame (NaN where a point was not seen), ``valid`` the poses fitted, ``sigma_mm``
    the noise per coordinate. Two points or more; with two, each one's error relative to the
    other's is the other's turned round, so which of them moved is not told: the index is -1."""
    K, M, _ = residual.shape
    if M < 2 or not sigma_mm > 0:
        return None
    d = np.einsum("kji,kmj->kmi", R, residual)  # into the tool frame
    seen = np.isfinite(d).all(-1) & valid[:, None]
    best = None
    for j in range(M):
        others = np.delete(np.where(seen[..., None], d, np.nan), j, 1)
        n_others = np.isfinite(others).all(-1).sum(1)
        rel = d[:, j] - np.nan_to_num(others).sum(1) / np.maximum(n_others, 1)[:, None]
        ok = np.flatnonzero(seen[:, j] & (n_others > 0))
        n = len(ok)
        if n < 2 * MIN_SIDE:
            continue
        x = rel[ok]
        var = sigma_mm**2 * (1.0 + 1.0 / n_others[ok])  # each pose's relative residual's variance
        c, cv = np.cumsum(x, 0), np.cumsum(var)
        s = np.arange(MIN_SIDE, n - MIN_SIDE + 1)
        before = c[s - 1] / s[:, None]
        after = (c[-1] - c[s - 1]) / (n - s)[:, None]
        step = after - before
        noise = cv[s - 1] / s**2 + (cv[-1] - cv[s - 1]) / (n - s) ** 2  # per coordinate
        stat = np.sum(step**2, 1) / noise
        spread = np.sum((x - x.mean(0)) ** 2)
        share = (s * (n - s) / n) * np.sum(step**2, 1) / max(spread, 1e-300)
        k = int(np.argmax(np.where(share > MOVED_SHARE, stat, -np.inf)))
        if share[k] > MOVED_SHARE and stat[k] > MOVED_CHI2 and (best is None or np.sqrt(stat[k]) > best[4]):
            best = (j if M > 2 else -1, int(ok[s[k] - 1]), int(ok[s[k]]), step[k], float(np.sqrt(stat[k])))
    return best


DRIFT_CHI2 = 30.0
"""The trend's slope, squared, in units of its own noise (3 degrees of freedom) above which the
measurements are said to drift along the file: chi-square's tail there is 1e-6."""
DRIFT_SPAN = 3.0
"""And the drift over the rows fitted is at least this many times the residual's noise per
coordinate: a trend too small to matter next to the noise is not named."""


@dataclasses.dataclass(frozen=True)
class Drift:
    """The measurements' residual moving along the file's rows (:func:`drift`)."""

    change: np.ndarray
    """``(3,)`` mm, measured minus predicted: over the rows used (a line), or across the step."""
    sigmas: float
    """The slope, or the step, in units of its standard error."""
    noise: float
    """The residual's noise per coordinate about the line or the step (mm)."""
    rows: np.ndarray
    """The rows used, in order."""
    step: int | None = None
    """A step: the index into :attr:`rows` of the first row after it; ``None``: a line."""


def drift(
    rows: Float[np.ndarray, " K"],
    residual: Float[np.ndarray, "K M 3"],
    valid: Bool[np.ndarray, " K"],
) -> Drift | None:
    """How the measurements' residual, averaged over the points, moves along the file's row order:
    a line (a slow drift: warming, a creeping stand) or one step (a tracker or base knocked), the
    one of the two that leaves the smaller residual, where its slope or step is beyond chance
    (:data:`DRIFT_CHI2`) and large next to the noise (:data:`DRIFT_SPAN`); else None. The rows
    used are those ``valid`` with a finite residual. One fixed base frame averages such a move:
    no pose stands out, but every point's residual follows the row. The noise is the residual's
    own about the line or step (the model's misfit in it too), per coordinate."""
    with np.errstate(invalid="ignore"):
        r = np.nanmean(np.asarray(residual, float), 1)
    ok = np.asarray(valid, bool) & np.isfinite(r).all(-1)
    n = int(ok.sum())
    if n < 2 * MIN_SIDE:
        return None
    order = np.argsort(np.asarray(rows, float)[ok], kind="stable")
    used, x = np.asarray(rows)[ok][order], r[ok][order]
    found = []
    t = used - used.mean()
    A = np.stack([np.ones_like(t), t], 1).astype(float)
    coef = np.linalg.lstsq(A, x, rcond=None)[0]
    rss = np.sum((x - A @ coef) ** 2, 0)  # per coordinate
    var = rss / (n - 2)
    stat = float(np.sum(coef[1] ** 2 * np.sum(t**2) / np.maximum(var, 1e-300)))
    found.append(
        (float(rss.sum()), Drift(coef[1] * (t.max() - t.min()), np.sqrt(stat), float(np.sqrt(var.mean())), used))
    )
    c = np.cumsum(x, 0)
    k = np.arange(MIN_SIDE, n - MIN_SIDE + 1)
    before, after = c[k - 1] / k[:, None], (c[-1] - c[k - 1]) / (n - k)[:, None]
    rss_k = np.sum(x**2) - np.sum(k[:, None] * before**2 + (n - k)[:, None] * after**2, 1)
    b = int(np.argmin(rss_k))
    s, jump = int(k[b]), after[b] - before[b]
    var = (np.sum((x[:s] - before[b]) ** 2, 0) + np.sum((x[s:] - after[b]) ** 2, 0)) / (n - 2)
    stat = float(np.sum(jump**2 / np.maximum(var * (1.0 / s + 1.0 / (n - s)), 1e-300)))
    found.append((float(rss_k[b]), Drift(jump, np.sqrt(stat), float(np.sqrt(var.mean())), used, s)))
    real = [(e, d) for e, d in found if d.sigmas**2 > DRIFT_CHI2 and np.linalg.norm(d.change) > DRIFT_SPAN * d.noise]
    return min(real, key=lambda ed: ed[0])[1] if real else None
