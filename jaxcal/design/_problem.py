r"""The design problem: the information a pose set gives about the identifiable (base)
parameters of a calibration, and the three criteria computed from it.

A calibration with weights ``W = diag(1 / sigma^2)`` estimates the base parameters (the columns
:func:`jaxcal.calibration.base_set` keeps, as :func:`jaxcal.calibrate` does) with covariance
bounded below by the Cramér–Rao bound ``M(Q)^{-1}``, where
``M(Q) = sum_k J_b(q_k)^T W J_b(q_k)`` (+ a ridge prior's diagonal) and ``J_b`` are the base
columns of the identification Jacobian (paper eq. 10, :func:`jaxcal.model.jacobian`). The
parameters are scaled so that every column has unit RMS weighted norm per pose over the validation
set (mm and rad would otherwise weigh parameters arbitrarily). The criteria:

* ``d`` (D-optimal): ``log det M``, larger is better;
* ``a`` (A-optimal): ``tr M^{-1}``, the summed variance of the scaled parameters;
* ``validation``: ``sqrt(tr(M^{-1} S))`` with ``S = mean_v G_v^T G_v`` over validation poses
  ``v``, ``G_v`` the position rows of the tool point(s): the expected RMS position error (mm)
  of the calibrated model at the validation poses, the CRLB propagated through the model to
  first order.

Every criterion is a smooth function of the joint values, differentiated by JAX through the
analytic Jacobian. The criterion is chosen by dynamic weights, so one compiled program serves
all three.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import as_f64, jit
from ..calibration import (
    Options,
    base_set,
    generic_model,
    lever,
    make_layout,
    nominal_model,
    parallel_snapped,
    parse_params,
)
from ..errors import DataError
from ..kinematics import check_q
from ..model import Layout, Model, apply, jacobian, predict, row_weights
from ..robot import Robot
from ._report import report_options

CRITERIA = ("d", "a", "validation")
DEFAULT_SIGMA_POS_MM = 0.02
DEFAULT_SIGMA_ROT_RAD = 2e-5
DEFAULT_POINT_MM = 1.0
"""Distance of the measured points from the tool origin when none are given (generic
directions): off the last joint's axis, as a real marker is, yet where the tool origin is for
a region or a view."""


LIMIT_MARGIN = 0.02
"""Share of a joint's range a gradient design keeps free at either end of its limits."""


class DesignProblem(eqx.Module):
    """What a criterion needs, built by :func:`design_problem` (arrays; the layout and the base
    columns static)."""

    model: Model
    """The nominal model (the robot's structure, the measured points)."""
    scale: Float[Array, " b"]
    """Column scale of the base parameters."""
    row_weights: Float[Array, " rows"]
    """``1 / sigma`` per residual row of a pose."""
    prior: Float[Array, " b"]
    """Diagonal information of a ridge prior, scaled (0 without)."""
    val_factor: Float[Array, "b b"]
    """``F`` with ``F^T F = S`` (scaled): the validation criterion is ``tr(F M^{-1} F^T)``."""
    weights: Float[Array, " 3"]
    """One-hot selection of the criterion (``d``, ``a``, ``validation``)."""
    lower: Float[Array, " n"]
    upper: Float[Array, " n"]
    margin: Float[Array, " n"]
    """How far inside its limits a designed configuration stays, per joint (rad; mm for a
    prismatic joint): a real arm faults at its hard limits, where an optimum tends to lie."""
    layout: Layout = eqx.field(static=True)
    base: tuple[int, ...] = eqx.field(static=True)
    bounded: tuple[bool, ...] = eqx.field(static=True)
    """Per joint: its limits are the robot file's (else :attr:`lower`, :attr:`upper` are only a
    range to design in, and a pool's or a pose file's values may lie beyond it)."""

    @property
    def criterion(self) -> str:
        return CRITERIA[int(np.argmax(np.asarray(self.weights)))]

    @property
    def n_base(self) -> int:
        return len(self.base)

    def base_names(self) -> tuple[str, ...]:
        names = self.layout.names()
        return tuple(names[i] for i in self.base)


def information(problem: DesignProblem, q: Float[Array, "K n"]) -> Float[Array, "b b"]:
    r"""Fisher information ``M = sum_k J_b^T W J_b + prior`` of the scaled base parameters over
    the poses ``q`` (the inverse of the Cramér–Rao bound)."""
    L = blocks(problem, q)
    return jnp.einsum("krb,krc->bc", L, L) + jnp.diag(problem.prior)


def blocks(problem: DesignProblem, q: Float[Array, "K n"]) -> Float[Array, "K rows b"]:
    """Weighted, scaled base-set rows of each pose: ``M = sum_k L_k^T L_k``."""
    J = identification_jacobian(problem.model, problem.layout, q)[..., list(problem.base)]
    return J * problem.scale * problem.row_weights[:, None]


def identification_jacobian(model: Model, layout: Layout, q: Float[Array, "K n"]) -> Float[Array, "K rows m"]:
    """:func:`jaxcal.model.jacobian` by reverse-mode autodiff of the measurement model
    (:func:`jaxcal.model.apply`, :func:`jaxcal.model.predict`), pose by pose: the same matrix (the
    tests compare them), whose derivative with respect to ``q``, which the design's gradient
    needs, compiles in a fraction of the time the analytic form's does (that form's entry-by-entry
    expressions are built for first-order speed). Rows as the model's: positions, then for poses
    the rotation ``vee(dR R^T)``."""

    def one(qk):
        qk = qk[None]
        if layout.n_points:
            return jax.jacrev(lambda x: predict(apply(model, layout, x), qk).reshape(-1))(jnp.zeros(layout.size))
        R0 = predict(model, qk)[0, :3, :3]

        def pose(x):
            T = predict(apply(model, layout, x), qk)[0]
            W = T[:3, :3] @ R0.T  # I + skew(w) to first order
            return jnp.concatenate([T[:3, 3], jnp.stack([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2])

        return jax.jacrev(pose)(jnp.zeros(layout.size))

    return jax.vmap(one)(q)


def measures(problem: DesignProblem, M: Float[Array, "b b"]) -> Float[Array, " 3"]:
    """``[log det M, tr M^{-1}, tr(F M^{-1} F^T)]`` through one Cholesky factor (NaN when ``M``
    is not positive definite)."""
    C = jnp.linalg.cholesky(M)
    Ci = jax.scipy.linalg.solve_triangular(C, jnp.eye(M.shape[0]), lower=True)  # C^-1: M^-1 = Ci^T Ci
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diagonal(C)))
    return jnp.stack([logdet, jnp.sum(Ci**2), jnp.sum((Ci @ problem.val_factor.T) ** 2)])


def loss_of(problem: DesignProblem, m: Float[Array, " 3"]) -> Float[Array, ""]:
    """The minimised form of the selected criterion: ``-log det M / b`` (D), ``log tr`` (A,
    validation): each changes by O(1) for a relative change of the information, whatever the
    robot's size."""
    terms = jnp.stack([-m[0] / problem.n_base, jnp.log(m[1]), jnp.log(m[2])])
    return jnp.sum(jnp.where(problem.weights > 0, terms, 0.0))


def loss(problem: DesignProblem, q: Float[Array, "K n"]) -> Float[Array, ""]:
    """The selected criterion of the poses ``q`` in its minimised form (:func:`loss_of`): the
    function the pose optimisation differentiates."""
    return loss_of(problem, measures(problem, information(problem, q)))


def values_of(m) -> dict:
    """The three criteria in their reported units from :func:`measures`."""
    m = np.asarray(m, dtype=np.float64)
    if not np.all(np.isfinite(m)):  # too few poses: the information is singular
        return {"log_det": -np.inf, "a_trace": np.inf, "validation_rms_mm": np.inf}
    return {"log_det": float(m[0]), "a_trace": float(m[1]), "validation_rms_mm": float(np.sqrt(m[2]))}


def measures_batch(problem: DesignProblem, q) -> np.ndarray:
    """:func:`measures` of many pose sets ``q (R, K, n)`` at once, ``(R, 3)``."""
    q = np.asarray(q)
    L = pose_blocks(problem, q.reshape(-1, q.shape[-1])).reshape(q.shape[:2] + (-1, problem.n_base))
    return measures_of_information(problem, np.einsum("rkab,rkac->rbc", L, L) + np.diag(np.asarray(problem.prior)))


def measures_of_information(problem: DesignProblem, M) -> np.ndarray:
    """:func:`measures` of many information matrices ``M (R, b, b)`` at once, ``(R, 3)``, in
    chunks of :data:`MEASURES_CHUNK`: one compiled program whatever ``R``."""
    M = np.asarray(M)
    R = len(M)
    padded = np.concatenate([M, np.broadcast_to(np.eye(M.shape[-1]), (-R % MEASURES_CHUNK,) + M.shape[1:])])
    n = MEASURES_CHUNK
    out = [np.asarray(_measures_of(problem, jnp.asarray(padded[s : s + n]))) for s in range(0, R, n)]
    return np.concatenate(out)[:R]


MEASURES_CHUNK = 256
"""Pose sets per call of the one compiled program of :func:`measures_batch`."""


@eqx.filter_jit
def _measures_of(problem: DesignProblem, M):
    return jax.vmap(lambda M_: measures(problem, M_))(M)


def evaluate(problem: DesignProblem, q) -> dict:
    """All three criteria of the poses ``q (K, n)``: ``log_det``, ``a_trace`` and
    ``validation_rms_mm`` (module docstring), whichever criterion the problem selects."""
    q = _checked_q(problem, q, "q")
    return values_of(measures_batch(problem, q[None])[0])


def value(name: str, values: dict) -> float:
    """The reported value of criterion ``name`` from :func:`evaluate`'s dict."""
    return values[{"d": "log_det", "a": "a_trace", "validation": "validation_rms_mm"}[name]]


def better(name: str, a: float, b: float) -> bool:
    """Whether value ``a`` of criterion ``name`` is better than ``b`` (D: larger)."""
    return a > b if name == "d" else a < b


def _checked_q(problem: DesignProblem, q, name: str) -> np.ndarray:
    q = np.asarray(as_f64(q, name))
    n = problem.lower.shape[0]
    if q.ndim != 2 or q.shape[1] != n:
        raise DataError(f"{name} must have shape (K, {n}), got {q.shape}", option=name)
    bad = ~np.isfinite(q)
    if bad.any():
        k, j = np.argwhere(bad)[0]
        raise DataError(f"{name}: row {k}, joint {j + 1}: value is not finite", option=name)
    return q


def tool_positions(model: Model, layout: Layout, q: Float[Array, "K n"]) -> Float[Array, "K P 3"]:
    """Positions (mm, in the frame of the forward kinematics) of what is measured: the tool
    origin for poses, the points for points."""
    pred = predict(model, q)
    return pred[..., None, :3, 3] if layout.n_points == 0 else pred


JACOBIAN_CHUNK = 256
"""Poses per call of the one compiled Jacobian program (:func:`reference`) of a design."""


def _reference_of(model: Model, layout: Layout, q):
    # values only: the analytic Jacobian traces and compiles faster than the autodiff one, which
    # the optimiser needs for its derivative in q
    return jacobian(model, layout, q), tool_positions(model, layout, q)


# run a few times per design on a few hundred poses: XLA's optimisations would cost more
# compile time than they save (the values are the same)
_reference = jit(_reference_of)


def reference(model: Model, layout: Layout, q) -> tuple[np.ndarray, np.ndarray]:
    """The identification Jacobian ``(K, rows, m)`` and the measured points' positions ``(K, P,
    3)`` at the poses ``q (K, n)``, in chunks of :data:`JACOBIAN_CHUNK` poses: whatever the
    count (validation poses, random sets, a pool, candidates), one compiled program."""
    q = np.asarray(q, dtype=np.float64)
    K = len(q)
    padded = np.concatenate([q, np.repeat(q[-1:], -K % JACOBIAN_CHUNK, 0)])
    n = JACOBIAN_CHUNK
    parts = [_reference(model, layout, jnp.asarray(padded[s : s + n])) for s in range(0, K, n)]
    return tuple(np.concatenate([np.asarray(p[i]) for p in parts])[:K] for i in (0, 1))


def pose_blocks(problem: DesignProblem, q) -> np.ndarray:
    """:func:`blocks` of the poses ``q (K, n)`` through :func:`reference`'s program."""
    J = reference(problem.model, problem.layout, q)[0][..., list(problem.base)]
    return J * np.asarray(problem.scale) * np.asarray(problem.row_weights)[:, None]


def uniform_poses(robot: Robot, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` joint configurations uniform within the joint limits."""
    lim = np.asarray(robot.q_limits)
    return lim[:, 0] + rng.uniform(size=(n, len(lim))) * (lim[:, 1] - lim[:, 0])


def count(name: str, v, lo: int) -> int:
    """``v`` checked as an integer >= ``lo`` (a DataError naming ``name`` otherwise)."""
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
        raise DataError(f"{name} must be an integer >= {lo}, got {v!r}", option=name)
    return int(v)


def options_of(options: Options | None, kw: dict) -> Options:
    """``options`` with keyword overrides, checked; unknown keywords name the known ones."""
    base = Options() if options is None else options
    known = {f.name for f in dataclasses.fields(Options)}
    unknown = sorted(set(kw) - known)
    if unknown:
        raise DataError(f"unknown option(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}", option=unknown[0])
    return dataclasses.replace(base, **kw).checked()


STRUCTURE_POSES = 200
"""Poses uniform within the joint limits on which the base set (what a calibration of designed
poses identifies) and the column scales are found."""


def design_problem(
    robot: Robot,
    options: Options | None = None,
    /,
    *,
    criterion: str = "validation",
    n_points: int = 0,
    points=None,
    q_val=None,
    n_val: int = 200,
    seed: int = 0,
    params_from=None,
    limit_margin: float = LIMIT_MARGIN,
    **kw,
) -> DesignProblem:
    """The design problem of a calibration of ``robot`` with these options.

    **Arguments**

    * ``options`` / keywords: :class:`jaxcal.Options`, as for :func:`jaxcal.calibrate`: the
      layout (``estimate_base``, ``estimate_tool``, ``camera``), the parameter set (``params``,
      ``compliance``, ``ridge_mm``: the calibration's prior, each parameter weighed by its lever
      over the validation poses; ``auto`` is ``all`` as in a single fit) and the noise (``sigma_pos_mm``,
      ``sigma_rot_rad``; None: 0.02 mm and 2e-5 rad, which only weigh rotation rows against
      position rows).
    * ``criterion``: ``"validation"`` (default), ``"d"`` or ``"a"`` (module docstring).
    * ``n_points``: 0 to measure the tool's pose, ``M >= 1`` to measure ``M`` points on the tool
      (position only); ``points (M, 3)`` their positions in the tool frame (mm; default:
      :data:`DEFAULT_POINT_MM` from the tool origin in generic directions when the tool is
      estimated, as no real marker lies on the last joint's axis, where a point at the origin
      would hide that joint's parameters and make the criteria optimistic; at the origin of a
      known tool).
    * ``q_val (V, n)``: the validation poses; default ``n_val`` poses uniform within the joint
      limits, drawn with ``seed``. The base set, the column scale and the prior's levers are
      those of :data:`STRUCTURE_POSES` (or ``n_val``, if more) such poses, whatever ``q_val``:
      the parameters a calibration on the designed poses estimates, where the arm will work or
      not.
    * ``params_from``: a ``jaxcal calibrate --json`` report (path or dict): design for the
      parameters that calibration estimated, with its prior, compliances, ``estimate_base`` and
      ``estimate_tool`` (:func:`jaxcal.design.report_options`); keywords given here win over
      the report.
    * ``limit_margin``: the share of each joint's range a gradient design keeps free at either
      end of the limits the robot gives (none for a joint given none: its range is a sampling
      range); a pool's rows and the random sets are taken as they are.
    """
    if criterion not in CRITERIA:
        raise DataError(f"criterion must be one of {', '.join(CRITERIA)}, got {criterion!r}", option="criterion")
    if params_from is not None:
        kw = report_options(params_from, robot) | kw
    opts = options_of(options, kw)
    for name, v, lo in (("n_points", n_points, 0), ("n_val", n_val, 1), ("seed", seed, 0)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise DataError(f"{name} must be an integer >= {lo}, got {v!r}", option=name)
    if points is not None:
        points = np.asarray(as_f64(points, "points"))
        if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
            raise DataError(f"points must be finite with shape (M, 3), got {points.shape}", option="points")
        if n_points not in (0, points.shape[0]):
            raise DataError(f"n_points is {n_points} but points has {points.shape[0]} rows", option="points")
        n_points = points.shape[0]
    layout = make_layout(robot, opts, int(n_points))
    if points is None:
        model = generic_model(robot, layout, DEFAULT_POINT_MM)
    else:  # nearly parallel axes parallel, as in the generic model: the set a calibration chooses
        model = parallel_snapped(eqx.tree_at(lambda m: m.points, nominal_model(robot, layout), jnp.asarray(points)))
    # the arm's whole range: the set a calibration on designed poses identifies, and the scales;
    # validation poses where the arm will work may move fewer joints, or be few
    whole = uniform_poses(robot, max(int(n_val), STRUCTURE_POSES), np.random.default_rng([int(seed), 1]))
    given = q_val is not None
    if not given:
        q_val = whole[: int(n_val)]
    q_val = np.asarray(check_q(robot, as_f64(q_val, "q_val")))
    if q_val.ndim != 2 or q_val.shape[0] < 1:
        raise DataError(f"q_val must have shape (V, {robot.n_joints}) with V >= 1, got {q_val.shape}", option="q_val")
    J = reference(model, layout, whole)[0]  # (N, rows, m)

    # the identifiable set as calibrate finds it on poses over the whole range
    frames, cams, comps = list(layout.frames), list(layout.cameras), list(layout.compliances)
    ident = base_set(J, layout, robot)
    spec = "all" if opts.params == "auto" else opts.params
    cand = parse_params(spec, robot, opts.ridge_mm, compliance=opts.compliance == "yes")[0]
    estimated = set(frames + cams + list(cand.dh) + (comps if cand.compliance else []))
    base = tuple(i for i in ident.base if i in estimated)
    if not base:
        raise DataError("no identifiable parameter to design for (check params)", option="params")
    sp = DEFAULT_SIGMA_POS_MM if opts.sigma_pos_mm is None else opts.sigma_pos_mm
    sr = DEFAULT_SIGMA_ROT_RAD if opts.sigma_rot_rad is None else opts.sigma_rot_rad
    w = np.asarray(row_weights(layout, sp, sr))
    Jb = J[..., list(base)]
    scale = 1.0 / np.sqrt(np.mean(np.sum((Jb * w[:, None]) ** 2, axis=1), axis=0))
    # the calibration's physically scaled prior, its levers over the whole range (a calibration
    # takes them over its own poses, the ones being designed)
    lev = lever(J, layout.n_points)
    kinematic = set(range(layout.n_kin)) | set(comps)
    prior = np.array([cand.prior_weight(lev[i]) if i in kinematic else 0.0 for i in base]) ** 2 * scale**2
    # validation: the position rows of every measured point (the tool origin for poses), averaged
    # over points and poses
    Jv = reference(model, layout, q_val)[0] if given else J[: len(q_val)]
    Jv = Jv[..., list(base)]
    G = (Jv[:, :3] if layout.n_points == 0 else Jv) * scale
    S = np.einsum("vrb,vrc->bc", G, G) / (len(q_val) * max(layout.n_points, 1))
    lam, U = np.linalg.eigh((S + S.T) / 2)
    F = np.sqrt(np.clip(lam, 0.0, None))[:, None] * U.T
    lim = np.asarray(robot.q_limits)
    real = isinstance(limit_margin, (int, float, np.integer, np.floating)) and not isinstance(limit_margin, bool)
    if not (real and 0 <= limit_margin < 0.5):
        raise DataError(
            f"limit_margin must be a share of the range in [0, 0.5), got {limit_margin!r}", option="limit_margin"
        )
    margin = limit_margin * (lim[:, 1] - lim[:, 0]) * robot.limits_given()
    return DesignProblem(
        model=model,
        scale=jnp.asarray(scale),
        row_weights=jnp.asarray(w),
        prior=jnp.asarray(prior),
        val_factor=jnp.asarray(F),
        weights=jnp.asarray(np.eye(3)[CRITERIA.index(criterion)]),
        lower=jnp.asarray(lim[:, 0]),
        upper=jnp.asarray(lim[:, 1]),
        margin=jnp.asarray(margin),
        layout=layout,
        base=base,
        bounded=tuple(bool(b) for b in robot.limits_given()),
    )


def with_criterion(problem: DesignProblem, criterion: str) -> DesignProblem:
    """The same problem with another criterion (same compiled programs)."""
    if criterion not in CRITERIA:
        raise DataError(f"criterion must be one of {', '.join(CRITERIA)}, got {criterion!r}", option="criterion")
    return eqx.tree_at(lambda p: p.weights, problem, jnp.asarray(np.eye(3)[CRITERIA.index(criterion)]))
