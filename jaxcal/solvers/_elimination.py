"""The paper's joint-by-joint "elimination" calibration (section 2.3, eq. 11-14), made honest.

Error model (eq. 10, adjoint form): the spatial error twist of a pose is
$\\xi(q) = \\sum_i J_i(q) x_i$, with joint ``i``'s columns $J_i = \\mathrm{Ad}(T_i)\\,\\mathrm{vee}(\\Omega_i)$
(:func:`jaxcal.error_model.twist_jacobian`). In SDH, the ``theta_i``/``d_i`` columns are twists
about/along ``z_{i-1}`` and depend only on ``q_1..q_{i-1}``; the ``a_i``/``alpha_i`` columns
depend on ``q_1..q_i``. A pair of poses sharing ``q_1..q_{n-2}`` (:func:`design_poses`) therefore
has a difference $D = \\xi' - \\xi''$ (eq. 11) in which every column of joints ``1..n-2`` and the
``theta_{n-1}``, ``d_{n-1}`` columns vanish *exactly*; what is left are the 6 unknowns
``(theta_n, d_n, a_n, alpha_n, a_{n-1}, alpha_{n-1})`` plus later joints, already known. Steps
``n = N..2`` solve these blocks back to front (keep joint ``n``, discard ``n-1``, except
``a_1, alpha_1`` kept at step 2); joint 1's ``theta``, ``d`` come from undifferenced poses.

Two variants, both pure, jit-able and vmapped over robots by :func:`eliminate_batch`:

* **literal** (``literal=True``): one pass around the nominal model, ``D`` from the paper's
  first-order ``dT T^{-1}`` (``vee(T_meas T^{-1} - I)``), every step's full 6-column block solved
  with the normal equations (a plain inverse), no weights. Singular where the block is.
* **robust**: (1) per-step *base columns* chosen on the nominal model at design time
  (:func:`make_plan`: in-order greedy rank test on the unit-norm-scaled block, relative threshold
  ``rtol = 1e-8``, :func:`jaxcal.identifiability.analyze`); a column left out is held at 0 and
  its effect lands in the parameters that are identifiable where it shows (e.g. ``d2``
  estimates ``d2 + d3`` on arms with parallel axes 2, 3); (2) each block is solved by
  column-scaled Householder-QR least squares on those base columns after
  whitening every pair with its measurement-noise covariance in twist coordinates;
  (3) re-linearisation: frames, Jacobians and measured twists ``log(T_meas T(x)^{-1})`` are
  recomputed around the current estimate in a ``lax.while_loop`` until ``max|dx| < tol``.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..error_model import param_names, perturb, twist_jacobian
from ..errors import DataError
from ..identifiability import analyze
from ..kinematics import fk
from ..lie import inv_transform, skew, vee
from ..robot import Robot
from . import _small_linalg as small
from ._elimination_design import PairLayout, infer_layout


@dataclasses.dataclass(frozen=True)
class StepInfo:
    """One step's block on the nominal model (hashable)."""

    joint: int
    """Joint calibrated by the step (1 = the absolute step for theta_1, d_1)."""
    columns: tuple[int, ...]
    """Parameter indices of the block's columns (literal variant solves them all)."""
    free: tuple[int, ...]
    """Base columns kept by the robust variant."""
    owned: tuple[int, ...]
    """Parameters this step writes (the others in ``free`` are discarded)."""
    cond_raw: float
    """Condition number of the unscaled block (mm and rad columns as they are)."""
    cond_scaled: float
    """Condition number with unit-norm columns (inf if a column is zero)."""
    cond_free: float
    """Condition number of the scaled base columns (what the robust solve sees)."""


@dataclasses.dataclass(frozen=True)
class EliminationPlan:
    """Static description of an elimination solve: layout, steps, identifiable set."""

    layout: PairLayout
    steps: tuple[StepInfo, ...]
    """Differencing steps ``n = N..2``, then the absolute step (joint 1)."""
    names: tuple[str, ...]

    @property
    def identified(self) -> tuple[int, ...]:
        return tuple(sorted(j for s in self.steps for j in s.owned if j in s.free))

    @property
    def fixed(self) -> tuple[int, ...]:
        return tuple(j for j in range(len(self.names)) if j not in self.identified)

    def report(self) -> str:
        nm = self.names
        lines = [f"{'step':>5s} {'cond raw':>10s} {'cond scaled':>12s} {'cond base':>10s}  held at 0"]
        for s in self.steps:
            lab = f"n={s.joint}" if s.joint > 1 else "abs"
            out = [nm[j] for j in s.columns if j not in s.free]
            lines.append(
                f"{lab:>5s} {s.cond_raw:10.3g} {s.cond_scaled:12.3g} {s.cond_free:10.3g}  " + (", ".join(out) or "-")
            )
        lines.append("not identified by the design (held at 0): " + (", ".join(nm[j] for j in self.fixed) or "none"))
        return "\n".join(lines)


LITERAL_MAX_CONDITION = 1e8
"""The literal variant fails (``ok`` False) where a step's column-scaled block is worse
conditioned than this on the design: its normal equations (the condition squared) are beyond
float64's precision, and their plain inverse returns rounding error."""


def _cond(A) -> float:
    s = np.linalg.svd(A, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def _blocks(robot: Robot, q, layout: PairLayout):
    """Nominal step blocks ``(joint, columns, A)`` as NumPy arrays, ``A`` stacked ``(rows, 6 or 2)``."""
    J = np.asarray(twist_jacobian(robot, jnp.asarray(q)))
    out = []
    for n in layout.steps:
        r0, r1 = layout.rows(n)
        cols = tuple(4 * (n - 1) + k for k in range(4)) + (4 * (n - 2) + 2, 4 * (n - 2) + 3)
        A = (J[r0:r1:2] - J[r0 + 1 : r1 : 2])[..., list(cols)].reshape(-1, len(cols))
        out.append((n, cols, A))
    a0, a1 = layout.abs_rows()
    rows = slice(a0, a1) if layout.n_abs else slice(None)
    out.append((1, (0, 1), J[rows][..., [0, 1]].reshape(-1, 2)))
    return out


def make_plan(robot: Robot, q, layout: PairLayout | None = None, *, rtol: float = 1e-8) -> EliminationPlan:
    """Analyse a design ``q`` ``(K, N)`` on the nominal ``robot`` (NumPy, outside jit): each
    step's columns, base columns (rank test with relative threshold ``rtol`` on unit-norm
    columns) and condition numbers."""
    if robot.convention != "sdh":
        raise DataError("the elimination method is written for standard DH; convert with jaxcal.to_sdh")
    q = np.asarray(q, dtype=np.float64)
    layout = infer_layout(q, robot.n_joints) if layout is None else layout
    names = tuple(param_names(robot))
    steps = []
    for n, cols, A in _blocks(robot, q, layout):
        ident = analyze(A, [names[j] for j in cols], rtol=rtol)
        free = tuple(cols[i] for i in ident.base)
        owned = cols[:4] + (cols[4:] if n == 2 else ()) if n > 1 else cols
        norms = np.linalg.norm(A, axis=0)
        scaled = _cond(A / norms) if np.all(norms > 1e-10 * norms.max()) else float("inf")
        steps.append(
            StepInfo(
                joint=n,
                columns=cols,
                free=free,
                owned=owned,
                cond_raw=_cond(A),
                cond_scaled=scaled,
                cond_free=float(ident.condition_number),
            )
        )
    return EliminationPlan(layout=layout, steps=tuple(steps), names=names)


def step_conditions(robot: Robot, q, layout: PairLayout | None = None) -> list[dict]:
    """Per-step condition numbers of design ``q`` on the nominal model, as dicts (for reports)."""
    plan = make_plan(robot, q, layout)
    return [
        {
            "joint": s.joint,
            "columns": [plan.names[j] for j in s.columns],
            "cond_raw": s.cond_raw,
            "cond_scaled": s.cond_scaled,
            "cond_base": s.cond_free,
            "held_at_zero": [plan.names[j] for j in s.columns if j not in s.free],
        }
        for s in plan.steps
    ]


# ----------------------------------------------------------------------------------------------
# the solve (pure JAX)


def _pose_cov(p, sigma_pos, sigma_rot):
    """Cholesky factor of the noise covariance of a measured twist ``[v, w]`` with
    ``v = dp + p x dr``: ``N diag(sp^2, sr^2) N^T``, ``N = [[I, skew(p)], [0, I]]``."""
    S = skew(p)
    St = jnp.swapaxes(S, -1, -2)
    eye = jnp.broadcast_to(jnp.eye(3), S.shape)
    top = jnp.concatenate([sigma_pos**2 * eye + sigma_rot**2 * S @ St, sigma_rot**2 * S], -1)
    bot = jnp.concatenate([sigma_rot**2 * St, sigma_rot**2 * eye], -1)
    return jnp.concatenate([top, bot], -2)


def _whiten(cov, *arrs):
    L = small.cholesky(jnp.where(jnp.isfinite(cov), cov, 1.0))
    return [small.solve_lower(L, a) for a in arrs]


def _lstsq_scaled(A, b):
    """Column-scaled least squares by Householder QR (the block's base columns have full rank by
    construction, :func:`make_plan`). Non-finite input gives NaN (checked by the caller)."""
    bad = ~(jnp.all(jnp.isfinite(A)) & jnp.all(jnp.isfinite(b)))
    A, b = jnp.where(bad, 0.0, A), jnp.where(bad, 0.0, b)
    y = small.lstsq_normal(A, b)  # no LAPACK custom calls in the loop (see _small_linalg)
    return jnp.where(bad, jnp.nan, y)


def _normal_solve(A, b):
    return jnp.linalg.solve(A.T @ A, A.T @ b)  # literal: one pass, no loop, a plain inverse


def _sweep(
    model: Robot, q, measured, plan: EliminationPlan, literal: bool, sigma_pos, sigma_rot, stacked: bool = False
):
    """One back-to-front pass of the elimination around ``model``: returns the update ``dx``.

    ``stacked=True`` (a diagnostic, not the paper's method) solves the same whitened differenced
    and absolute rows in one least-squares problem instead of step by step."""
    m = 4 * model.n_joints
    T = fk(model, q)
    E = measured @ inv_transform(T)
    if literal:
        xi = vee(E - jnp.eye(4))  # the paper's first-order dT T^-1
    else:
        import jaxlie

        xi = jaxlie.SE3.from_matrix(E).log()
    J = twist_jacobian(model, q)
    cov = _pose_cov(T[:, :3, 3], sigma_pos, sigma_rot)
    lay = plan.layout
    dx = jnp.zeros(m)
    rows_A, rows_b = [], []
    for st in plan.steps:
        cols = st.columns if literal else st.free
        if st.joint > 1:
            r0, r1 = lay.rows(st.joint)
            A = J[r0:r1:2] - J[r0 + 1 : r1 : 2]
            b = xi[r0:r1:2] - xi[r0 + 1 : r1 : 2]
            if not literal:
                A, b = _whiten(cov[r0:r1:2] + cov[r0 + 1 : r1 : 2], A, b[..., None])
                b = b[..., 0]
        else:
            a0, a1 = lay.abs_rows()
            rows = slice(a0, a1) if (literal and lay.n_abs) else slice(None)
            A, b = J[rows], xi[rows]
            if not literal:
                A, b = _whiten(cov[rows], A, b[..., None])
                b = b[..., 0]
        if stacked:
            rows_A.append(A.reshape(-1, m))
            rows_b.append(b.reshape(-1))
            continue
        # subtract the known contributions (dx is non-zero only on joints already solved)
        b = (b - A @ dx).reshape(-1)
        A = A[..., jnp.asarray(cols)].reshape(-1, len(cols))
        y = _normal_solve(A, b) if literal else _lstsq_scaled(A, b)
        keep = [i for i, j in enumerate(cols) if j in st.owned]
        dx = dx.at[jnp.asarray([cols[i] for i in keep])].set(y[jnp.asarray(keep)])
    if stacked:
        free = jnp.asarray(plan.identified)
        y = _lstsq_scaled(jnp.concatenate(rows_A)[:, free], jnp.concatenate(rows_b))
        dx = dx.at[free].set(y)
    return dx


def eliminate(
    robot: Robot,
    q,
    measured,
    *,
    plan: EliminationPlan,
    literal: bool = False,
    sigma_pos=1.0,
    sigma_rot=1e-3,
    max_steps: int = 20,
    tol: float = 1e-10,
    stacked: bool = False,
):
    """Elimination calibration of one robot's data.

    **Arguments**: ``q`` ``(K, N)`` a design (:func:`design_poses`) whose layout and base columns
    ``plan`` describes (:func:`make_plan` on the nominal robot); ``measured`` ``(K, 4, 4)`` full
    poses; ``literal`` selects the paper's one-pass variant; ``sigma_pos`` (mm), ``sigma_rot``
    (rad) the measurement noise used to whiten the robust variant's pairs; ``max_steps`` and
    ``tol`` (``max |dx|`` in mm/rad) bound the re-linearisation; ``stacked`` (diagnostic) solves
    all differenced rows at once instead of joint by joint.

    **Returns** ``(x, ok, num_steps)``: the ``4N`` DH error vector (layout of
    :func:`jaxcal.error_model.param_names`, fixed parameters 0), whether the iteration met
    ``tol`` within ``max_steps`` with a finite result (literal: finite, and every step's block
    within :data:`LITERAL_MAX_CONDITION`), and the number of sweeps.
    """
    m = 4 * robot.n_joints
    if literal:
        x = _sweep(robot, q, measured, plan, True, sigma_pos, sigma_rot)
        # a step whose block is singular on the design (parallel axes) gives finite nonsense
        posed = max(st.cond_scaled for st in plan.steps) < LITERAL_MAX_CONDITION
        return x, jnp.all(jnp.isfinite(x)) & posed, jnp.asarray(1)

    def cond(state):
        _, it, step = state
        return (it < max_steps) & (step > tol)

    def body(state):
        x, it, _ = state
        dx = _sweep(perturb(robot, x), q, measured, plan, False, sigma_pos, sigma_rot, stacked)
        step = jnp.max(jnp.abs(dx))
        return x + dx, it + 1, jnp.where(jnp.isfinite(step), step, -1.0)

    x, it, step = jax.lax.while_loop(cond, body, (jnp.zeros(m), jnp.asarray(0), jnp.asarray(jnp.inf)))
    ok = (step >= 0) & (step <= tol) & jnp.all(jnp.isfinite(x))
    return x, ok, it


@eqx.filter_jit
def eliminate_batch(
    robot: Robot,
    q,
    measured,
    sigma_pos,
    sigma_rot,
    *,
    plan: EliminationPlan,
    literal: bool = False,
    max_steps: int = 20,
    tol: float = 1e-10,
    stacked: bool = False,
):
    """:func:`eliminate` vmapped over robots: ``q`` ``(R, K, N)``, ``measured`` ``(R, K, 4, 4)``;
    one compiled call. ``sigma_pos``/``sigma_rot`` are scalars (traced: no recompilation)."""
    fn = lambda q_, m_: eliminate(
        robot,
        q_,
        m_,
        plan=plan,
        literal=literal,
        sigma_pos=sigma_pos,
        sigma_rot=sigma_rot,
        max_steps=max_steps,
        tol=tol,
        stacked=stacked,
    )
    return jax.vmap(fn)(q, measured)


def calibrate_design_batch(
    robot: Robot,
    q,
    measured,
    sigma_pos,
    sigma_rot,
    *,
    literal: bool = False,
    max_steps: int = 20,
    tol: float = 1e-10,
    position_only: bool = False,
    base: bool = False,
    tool: bool = False,
):
    """Entry point used by :func:`jaxcal.calibrate_batch` (``method="elimination"`` /
    ``"elimination-literal"``): checks that ``q`` ``(R, K, N)`` is an elimination design (layout
    inferred), builds the :class:`EliminationPlan` on the nominal model from the first design, and runs
    :func:`eliminate_batch`. **Returns** ``(x, ok, num_steps, plan)``."""
    if position_only or base or tool:
        raise DataError(
            "the elimination method needs full-pose measurements and known base/tool frames "
            "(position_only, estimate_base and estimate_tool are not supported)"
        )
    q = np.asarray(q, dtype=np.float64)
    layout = infer_layout(q, robot.n_joints)
    plan = make_plan(robot, q[0], layout)
    x, ok, steps = eliminate_batch(
        robot,
        jnp.asarray(q),
        jnp.asarray(measured),
        jnp.float64(sigma_pos),
        jnp.float64(sigma_rot),
        plan=plan,
        literal=literal,
        max_steps=max_steps,
        tol=tol,
    )
    return x, ok, steps, plan
