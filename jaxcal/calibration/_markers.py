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


def drift(
    rows: Float[np.ndarray, " K"],
    residual: Float[np.ndarray, "K M 3"],
    valid: Bool[np.ndarray, " K"],
) -> tuple[np.ndarray, float, float, np.ndarray] | None:
    """``(the drift over the rows used (mm, 3-vector, measured minus predicted), the trend's
    slope in units of its standard error, the residual's noise per coordinate (mm), the rows
    used)`` where the measurements' residual, averaged over the points, trends linearly with the
    file's row order, else None. The rows used are those ``valid`` with a finite residual.
    One fixed base frame averages a tracker or base that moved along the session: no pose stands
    out, but every point's residual follows the row. The noise is the residual's own about the
    trend (the model's misfit in it too), per coordinate."""
    with np.errstate(invalid="ignore"):
        r = np.nanmean(np.asarray(residual, float), 1)
    ok = np.asarray(valid, bool) & np.isfinite(r).all(-1)
    if ok.sum() < 8:
        return None
    t = np.asarray(rows, float)[ok]
    t = t - t.mean()
    A = np.stack([np.ones_like(t), t], 1)
    coef = np.linalg.lstsq(A, r[ok], rcond=None)[0]
    var = np.sum((r[ok] - A @ coef) ** 2, 0) / (ok.sum() - 2)  # per coordinate
    stat = float(np.sum(coef[1] ** 2 * np.sum(t**2) / np.maximum(var, 1e-300)))
    span = coef[1] * (t.max() - t.min())
    noise = float(np.sqrt(np.mean(var)))
    if stat > DRIFT_CHI2 and np.linalg.norm(span) > DRIFT_SPAN * noise:
        return span, float(np.sqrt(stat)), noise, np.asarray(rows)[ok]
    return None
