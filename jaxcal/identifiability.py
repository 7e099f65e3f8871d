"""Identifiability of the calibration parameters: rank, base set, observability, CRLB.

A design-time analysis of the *nominal* robot's identification Jacobian stacked over a pose set
(:func:`jaxcal.error_model.identification_jacobian`). It runs on NumPy/SciPy, outside jit, and
is deterministic.

* Columns are scaled first (to unit norm by default), because they carry different units
  (mm per mm, mm per rad, rad per rad).
* The numerical **rank** is the number of singular values of the scaled Jacobian above
  `rtol * s_max`.
* The **base set** is picked by a deterministic in-order greedy walk: a column is kept when
  more than a fraction `tau` of it lies outside the span of the kept columns, with `tau` the
  largest of :data:`SEPARATION` whose walk reaches the rank (else: when it raises the numerical
  rank of the kept columns). A column that is new only by a rounding of the robot's angles
  (1.5708 for pi/2) thus never takes the place of one that carries the direction: such a base
  set would estimate it through a nearly parallel pair, condition ~1e6. When two parameters
  are interchangeable the *earlier* one in the parameter vector is kept (`d2` is kept, `d3`
  fixed). Solvers hold the other, **fixed**, parameters at 0.
* `swappable` (a calibration passes a URDF's joint-frame parameters, whose order is a
  heuristic): the set is then improved by swaps among those columns while a fixed column's
  combination carries more than :data:`DOMINANCE` times a kept one (the "maxvol" exchange).
  A parameter held while a near twin is kept would otherwise have its true error show in the
  twin, amplified (a shift held at 0 showing as a turn many times its size): the points are
  fitted alike, but the links between them are written far from the arm.
* A fixed parameter still moves the data; its effect is absorbed by base parameters. To first
  order the base estimate is `C @ x_true` with `C[:, base] = I`, `C[:, fixed] = beta`,
  `beta = lstsq(J_base, J_fixed)`; `"d2 + d3"` means the estimate of `d2` is really
  `d2 + d3`.
* **Observability indices** O1..O5 (Borm & Menq; Nahvi & Hollerbach) of the scaled base-set
  Jacobian with singular values `s` (r of them) and `rows` rows:
  `O1 = prod(s)^(1/r) / sqrt(rows)`, `O2 = s_min / s_max`, `O3 = s_min`,
  `O4 = s_min^2 / s_max` (noise amplification index), `O5 = 1 / sum(1/s)`.
* :func:`crlb`: covariance `inv(J_b^T W J_b)`, `W = diag(1 / sigma^2)`, that bounds every
  unbiased estimator of the base-set combinations.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from .errors import DataError

__all__ = ["Identifiability", "analyze", "crlb", "row_sigmas"]


@dataclasses.dataclass(frozen=True, eq=False)
class Identifiability:
    """Result of :func:`analyze`. Indices refer to columns of the Jacobian (parameters)."""

    names: tuple[str, ...]
    """All `m` parameter names."""
    rank: int
    """Numerical rank of the column-scaled Jacobian."""
    base: tuple[int, ...]
    """Column indices of the identifiable base set, ascending."""
    fixed: tuple[int, ...]
    """The other columns (held at 0 by solvers), ascending."""
    unidentifiable: tuple[str, ...]
    """Names of parameters whose column is numerically zero (no effect at all)."""
    combinations: tuple[str, ...]
    """For each base parameter that absorbs fixed ones, the combination it really estimates."""
    combination_matrix: np.ndarray
    """`(len(base), m)`: base estimate = `C @ x_true` to first order."""
    singular_values: np.ndarray
    """All `m` singular values of the column-scaled Jacobian, descending."""
    condition_number: float
    """`s_max / s_min` of the scaled base-set Jacobian."""
    indices: dict[str, float]
    """Observability indices `"O1"` .. `"O5"` of the scaled base-set Jacobian."""

    @property
    def base_names(self) -> tuple[str, ...]:
        return tuple(self.names[i] for i in self.base)

    @property
    def fixed_names(self) -> tuple[str, ...]:
        return tuple(self.names[i] for i in self.fixed)

    def reasons(self) -> dict[str, str]:
        """``{name: why}`` for every fixed (held at 0, not identified) parameter, in parameter
        order: no effect at all on this pose set, or not separable from named base parameters
        (whose estimates absorb it), or linearly dependent on the base set."""
        m = len(self.names)
        out = {}
        for j in self.fixed:
            name = self.names[j]
            if name in self.unidentifiable:
                out[name] = (
                    "no effect on the measurements over this pose set (zero column of the "
                    "identification Jacobian: e.g. a joint that never moves, or too few distinct poses)"
                )
                continue
            absorbers = [self.names[b] for i, b in enumerate(self.base) if abs(self.combination_matrix[i, j]) > 1e-6]
            if absorbers:
                out[name] = (
                    f"not separable from {', '.join(absorbers)} on this pose set (rank {self.rank} of {m}); "
                    f"held at 0, its effect is absorbed by their estimates"
                )
            else:
                out[name] = f"linearly dependent on the base set (rank {self.rank} of {m}); held at 0"
        return out

    def report(self) -> str:
        """Multi-line, human-readable summary."""
        m = len(self.names)
        absorbed = [self.names[i] for i in self.fixed if self.names[i] not in self.unidentifiable]
        lines = [
            f"rank {self.rank} of {m} ({m - self.rank} deficient)",
            f"fixed (held at 0): {', '.join(self.fixed_names) or 'none'}",
            f"  unidentifiable (no effect): {', '.join(self.unidentifiable) or 'none'}",
            f"  absorbed by base parameters: {', '.join(absorbed) or 'none'}",
        ]
        lines += ["base parameters that estimate combinations:"]
        lines += [f"  {c}" for c in self.combinations] or ["  none"]
        lines += [
            f"condition number (scaled base-set Jacobian): {self.condition_number:.4g}",
            "observability: " + ", ".join(f"{k} = {v:.4g}" for k, v in self.indices.items()),
        ]
        return "\n".join(lines)


def _as_2d(J) -> np.ndarray:
    J = np.asarray(J, dtype=np.float64)
    if J.ndim == 3:
        J = J.reshape(-1, J.shape[-1])
    if J.ndim != 2 or J.shape[0] == 0 or J.shape[1] == 0:
        raise DataError(f"J must have shape (rows, m) or (K, r, m) with rows, m > 0, got {np.shape(J)}")
    if not np.all(np.isfinite(J)):
        r, c = np.argwhere(~np.isfinite(J))[0]
        raise DataError(f"J has a non-finite entry at row {r}, column {c}")
    return J


def _n_above(A: np.ndarray, thr: float) -> int:
    return int(np.sum(np.linalg.svd(A, compute_uv=False) > thr)) if A.shape[1] else 0


SEPARATION = (1e-3, 1e-4, 1e-5, 1e-6)
"""Fractions of a column's effect that must lie outside the span of the columns kept before it,
tried in turn (the first that reaches the numerical rank wins). A column that adds a direction
only through a rounded angle (a right angle written as 1.5708 rad adds 4e-6 of its effect) is
then not kept in place of a column that carries that direction fully."""


def _separated(Js: np.ndarray, order, zero, rank: int, tau: float) -> list[int]:
    """The in-order greedy base set at separation ``tau``: a column is kept when the part of it
    outside the span of the kept columns is more than ``tau`` of its norm (scale-free)."""
    kept: list[int] = []
    Q = np.zeros((Js.shape[0], 0))
    for j in order:
        if len(kept) == rank:
            break
        if zero[j]:
            continue
        a = Js[:, j]
        r = a - Q @ (Q.T @ a)
        r = r - Q @ (Q.T @ r)  # Gram-Schmidt twice: orthogonal to working precision
        if np.linalg.norm(r) > tau * np.linalg.norm(a):
            kept.append(j)
            Q = np.c_[Q, r / np.linalg.norm(r)]
    return kept


DOMINANCE = 2.0
"""A base set is improved (``swappable`` of :func:`analyze`) while a fixed column's least-squares
combination carries more than this multiple of a kept column, in scaled units. Each swap
multiplies the volume of the kept columns by more than this, so the exchange ends; exact twins
(``d2 + d3``: 1) keep the earlier parameter."""


def _dominant(Js: np.ndarray, kept: list[int], zero, swappable: set[int]) -> list[int]:
    """``kept`` after swaps of its ``swappable`` columns for fixed ones (:data:`DOMINANCE`)."""
    kept = list(kept)
    for _ in range(4 * Js.shape[1]):
        inside = [i for i, j in enumerate(kept) if j in swappable]
        rest = [j for j in sorted(swappable) if j not in kept and not zero[j]]
        if not inside or not rest:
            break
        B = np.abs(np.linalg.lstsq(Js[:, kept], Js[:, rest], rcond=None)[0])[inside]
        i, k = np.unravel_index(int(np.argmax(B)), B.shape)
        if B[i, k] <= DOMINANCE:
            break
        kept[inside[i]] = rest[k]
    return kept


def _term(c: float, name: str) -> str:
    sign = "-" if c < 0 else "+"
    mag = f"{abs(c):.4g}"
    return f"{sign} {name}" if mag == "1" else f"{sign} {mag} {name}"


def analyze(J, names, *, rtol: float = 1e-8, col_scale=None, priority=None, swappable=None) -> Identifiability:
    """Rank, base set and observability of an identification Jacobian.

    **Arguments**

    * `J`: `(rows, m)` or `(K, r, m)` (stacked per pose), e.g. the nominal robot's
      `identification_jacobian(robot, Q, ...)`.
    * `names`: the `m` parameter names (`error_model.param_names(robot, base=, tool=)`).
    * `rtol`: relative threshold on singular values (`s > rtol * s_max` counts).
    * `col_scale`: optional positive `(m,)` typical magnitude of each parameter (mm, rad): the
      analysis is done on `J * col_scale`. Default: `1 / ||J[:, j]||` (unit-norm columns).
    * `priority`: the order in which columns are offered to the base set (default: column
      order). Of interchangeable parameters the one offered first is kept: a calibration offers
      the base and tool frames first, so the frames keep what belongs to them (a gauge).
    * `swappable`: columns among which the base set is then improved by swaps (module
      docstring, :data:`DOMINANCE`); default none.

    A column is *unidentifiable* (numerically zero) when its scaled norm is at most
    `rtol` times the largest scaled column norm, taking unscaled columns when `col_scale` is
    the default. Combination terms are printed when `|beta| > 1e-6` (unscaled units).
    """
    J = _as_2d(J)
    rows, m = J.shape
    names = tuple(str(n) for n in names)
    if len(names) != m:
        raise DataError(f"{len(names)} names for {m} Jacobian columns")
    if not (np.isfinite(rtol) and 0 < rtol < 1):
        raise DataError(f"rtol must be in (0, 1), got {rtol}")
    norms = np.linalg.norm(J, axis=0)
    if col_scale is None:
        zero = norms <= rtol * norms.max()
        scale = np.where(zero, 1.0, 1.0 / np.where(zero, 1.0, norms))
    else:
        scale = np.broadcast_to(np.asarray(col_scale, dtype=np.float64), (m,)).copy()
        if not np.all(np.isfinite(scale) & (scale > 0)):
            raise DataError("col_scale must be finite and positive")
        sn = norms * scale
        zero = sn <= rtol * sn.max()
    Js = J * scale
    Js[:, zero] = 0.0  # numerically zero columns: exactly zero, so they never look like noise rank
    if Js.shape[0] > Js.shape[1]:
        # J = Q R with Q orthonormal: R has J's singular values and the same linear relations
        # between columns (ranks of column subsets, least-squares combinations), in m rows
        Js = np.linalg.qr(Js, mode="r")
    sv = np.linalg.svd(Js, compute_uv=False)
    thr = rtol * sv[0] if sv[0] > 0 else np.inf
    rank = int(np.sum(sv > thr))

    order = list(range(m)) if priority is None else [int(j) for j in priority]
    if sorted(order) != list(range(m)):
        raise DataError(f"priority must be a permutation of the {m} columns")
    for tau in (t for t in SEPARATION if t > rtol):
        kept = _separated(Js, order, zero, rank, tau)
        if len(kept) == rank:
            break
    else:
        kept = []
        for j in order:
            if len(kept) == rank:
                break
            if not zero[j] and _n_above(Js[:, kept + [j]], thr) == len(kept) + 1:
                kept.append(j)
    if len(kept) < rank:  # borderline spectrum: top up with pivoted QR of what the kept set misses
        warnings.warn(
            f"greedy base set has {len(kept)} columns for numerical rank {rank}; "
            "topped up by pivoted QR (singular values near the threshold)",
            stacklevel=2,
        )
        rest = [j for j in order if j not in kept and not zero[j]]
        Q = np.linalg.qr(Js[:, kept])[0] if kept else np.zeros((Js.shape[0], 0))
        resid = Js[:, rest] - Q @ (Q.T @ Js[:, rest])
        import scipy.linalg

        piv = scipy.linalg.qr(resid, mode="r", pivoting=True)[1]
        kept += [rest[p] for p in piv[: rank - len(kept)]]
    if swappable is not None:
        kept = _dominant(Js, kept, zero, {int(j) for j in swappable})
    base = tuple(sorted(kept))
    fixed = tuple(j for j in range(m) if j not in base)
    b, f = list(base), list(fixed)

    beta_s = np.linalg.lstsq(Js[:, b], Js[:, f], rcond=None)[0] if f and b else np.zeros((len(b), len(f)))
    beta = scale[b][:, None] * beta_s / scale[f][None, :]
    beta[:, zero[f]] = 0.0
    C = np.zeros((len(b), m))
    C[:, b] = np.eye(len(b))
    C[:, f] = beta
    C.flags.writeable = False

    combos = []
    for i, j in enumerate(b):
        terms = [_term(beta[i, k], names[fj]) for k, fj in enumerate(f) if abs(beta[i, k]) > 1e-6]
        if terms:
            combos.append(" ".join([names[j]] + terms))

    s = np.linalg.svd(Js[:, b], compute_uv=False) if b else np.zeros(0)
    if len(s) and s[-1] > 0:
        cond = float(s[0] / s[-1])
        indices = {
            "O1": float(np.exp(np.mean(np.log(s))) / np.sqrt(rows)),
            "O2": float(s[-1] / s[0]),
            "O3": float(s[-1]),
            "O4": float(s[-1] ** 2 / s[0]),
            "O5": float(1.0 / np.sum(1.0 / s)),
        }
    else:
        cond, indices = float("inf"), {k: 0.0 for k in ("O1", "O2", "O3", "O4", "O5")}
    sv.flags.writeable = False
    return Identifiability(
        names=names,
        rank=rank,
        base=base,
        fixed=fixed,
        unidentifiable=tuple(names[j] for j in range(m) if zero[j]),
        combinations=tuple(combos),
        combination_matrix=C,
        singular_values=sv,
        condition_number=cond,
        indices=indices,
    )


def _row_sigma(J3, rows: int, row_sigma) -> np.ndarray:
    sig = np.asarray(row_sigma, dtype=np.float64)
    if sig.size == rows:
        sig = sig.reshape(rows)
    elif sig.size == 1 or (sig.ndim == 1 and sig.size in (3, 6) and rows % sig.size == 0):
        sig = np.tile(sig.reshape(-1), rows // sig.size)  # scalar, or a per-pose pattern
    else:
        try:
            sig = np.broadcast_to(sig, np.shape(J3)[:-1]).reshape(rows)
        except ValueError:
            raise DataError(f"row_sigma of shape {sig.shape} does not fit J of shape {np.shape(J3)}") from None
    if not np.all(np.isfinite(sig) & (sig > 0)):
        raise DataError("row_sigma must be finite and positive")
    return sig


def crlb(J, row_sigma, ident: Identifiability) -> np.ndarray:
    """Cramér–Rao bound of the base-set estimate: `inv(J_b^T W J_b)`, `W = diag(1/sigma^2)`.

    `J`: `(rows, m)` or `(K, r, m)`, the Jacobian `ident` was computed from (or any pose set
    with the same columns). `row_sigma`: standard deviation of each row's measurement noise
    (mm or rad): a scalar, one value per row (e.g. :func:`row_sigmas`), a per-pose pattern of
    3 or 6 values such as `[sp, sp, sp, sr, sr, sr]`, or anything broadcastable to
    `J.shape[:-1]`. Returns the
    `(len(base), len(base))` covariance, in the units of the base parameters, of the estimate
    of `C @ x_true` (see :attr:`Identifiability.combination_matrix`).
    """
    J2 = _as_2d(J)
    if J2.shape[1] != len(ident.names):
        raise DataError(f"J has {J2.shape[1]} columns, the analysis {len(ident.names)} parameters")
    sig = _row_sigma(J, J2.shape[0], row_sigma)
    return base_covariance(J2[:, list(ident.base)] / sig[:, None])


def base_covariance(Jb) -> np.ndarray:
    """``inv(Jb^T Jb)`` of row-weighted base-set columns ``Jb (..., rows, b)``, by a
    column-scaled QR (stacks of pose sets at once: ``(R, rows, b) -> (R, b, b)``)."""
    d = np.linalg.norm(Jb, axis=-2)  # (..., b) column scales
    if np.any(d == 0):
        where = "this pose set" if d.ndim == 1 else f"pose set {int(np.argwhere(d == 0)[0, 0])}"
        raise DataError(f"a base-set column is zero on {where}")
    Rinv = np.linalg.inv(np.linalg.qr(Jb / d[..., None, :], mode="r"))
    cov = (Rinv @ np.swapaxes(Rinv, -1, -2)) / (d[..., :, None] * d[..., None, :])
    return (cov + np.swapaxes(cov, -1, -2)) / 2


def row_sigmas(
    n_poses: int, *, position_only: bool = False, sigma_pos_mm: float, sigma_rot_rad: float | None = None
) -> np.ndarray:
    """Per-row noise standard deviations in the row order of `identification_jacobian`:
    `[sp, sp, sp, sr, sr, sr]` per pose (`[sp, sp, sp]` if `position_only`), flattened to
    `(n_poses * (3 | 6),)`."""
    if position_only:
        one = [sigma_pos_mm] * 3
    else:
        if sigma_rot_rad is None:
            raise DataError("sigma_rot_rad is needed unless position_only=True")
        one = [sigma_pos_mm] * 3 + [sigma_rot_rad] * 3
    one = np.asarray(one, dtype=np.float64)
    if not np.all(np.isfinite(one) & (one > 0)):
        raise DataError("sigmas must be finite and positive")
    return np.tile(one, int(n_poses))
