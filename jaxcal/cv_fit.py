"""The fitting engine of :mod:`jaxcal.crossval`: the fixed setup of a real-data calibration
(free parameter layout, identifiability, the pose-count check) and the batched fits of frames
only and of every candidate on every training mask, in two vmapped calls of
:mod:`jaxcal.solvers.manifold`.

## Objective
$\\min_y \\sum_{k \\in train} |W e_k(y)|^2 + \\sum_j (p_j y_j)^2$, ``e_k`` the pose error
(position mm, rotation vector rad) of the measured vs the modelled pose, ``W = diag(1/sigma_pos
x3, 1/sigma_rot x3)``, ``y`` the free entries of ``x``: the estimated frame twists and the
identifiable DH errors (base set of :func:`jaxcal.identifiability.analyze`, frames first, so a
DH error that a frame absorbs is the one held at 0). The prior weights ``p_j`` (extra residual
rows) make one compiled, vmapped solver serve every candidate parameter set:

* ``0``: the parameter is free;
* ``1 / s_j``: a ridge (Tikhonov) prior of standard deviation ``s_j`` (``s`` mm for lengths,
  ``s`` mrad for angles: 1 mm at 1 m lever arm);
* ``PIN`` (1e8): the parameter is held at 0 (not in the set).

## Noise weighting
``sigma_pos`` and ``sigma_rot`` are estimated on each training set from the residual of the
*frames-only* fit (nominal DH, base and tool estimated): the RMS per coordinate / per axis.
Frames-only residuals are dominated by the model error, which affects position and rotation
alike, so the ratio is a fair weighting of the two kinds of rows without knowing the sensor.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from .camera import n_params
from .error_model import identification_jacobian, param_names, pose_error
from .errors import DataError
from .identifiability import Identifiability, analyze
from .initial_guess import initial_frames
from .param_sets import Candidate
from .robot import Robot
from .solvers.manifold import Problem, fit_batch

PIN = 1e8
METHODS = ("gn", "lm", "linear")


# -- the batched solver (jaxcal.solvers.manifold) ---------------------------------------------

def _fitter(setup, method: str):
    """A jit-compiled, vmapped fit for one setup, cached on it (the robot is a compile-time
    constant)."""
    cache = setup.__dict__.setdefault("_fitters", {})
    if method not in cache:
        prob = _problem(setup)

        def fit(*args):
            return fit_batch(prob, *args, method=method, max_steps=setup.max_steps)

        cache[method] = jax.jit(fit)
    return cache[method]


# -- the engine --------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Setup:
    """Everything fixed before fitting: the robot, the data, the free parameter layout."""

    robot: Robot
    q: np.ndarray
    measured: np.ndarray
    position_only: bool
    estimate_base: bool
    estimate_tool: bool
    method: str
    candidates: tuple[Candidate, ...]
    ident: Identifiability
    """Identifiability of all 4n DH errors + frames over all poses (nominal DH, initial frames)."""
    free: tuple[int, ...]
    """Free entries of x: identifiable DH errors of the union of candidates, then frame twists."""
    n_dh_free: int
    n_needed: int = 0
    """Parameters the candidates need on a generic pose set (rank)."""
    max_steps: int = 50
    camera: str = "none"
    """The largest camera measurement model (:mod:`jaxcal.camera`) of the candidates: its
    unknowns are carried by every fit, each candidate frees its own model's prefix of them
    (all held at 0 in the frames-only stage)."""

    @property
    def names(self) -> list[str]:
        return param_names(self.robot, base=True, tool=True)


def _frame_cols(robot, position_only, estimate_base, estimate_tool):
    n4 = 4 * robot.n_joints
    cols = list(range(n4, n4 + 6)) if estimate_base else []
    if estimate_tool:
        cols += list(range(n4 + 6, n4 + 9 if position_only else n4 + 12))
    return cols


def make_setup(robot: Robot, q, measured, *, position_only: bool, candidates, estimate_base=True,
               estimate_tool=True, method="gn", max_steps=50, camera="none") -> Setup:
    """Identifiability over all poses (at the all-pose initial frames) and the free layout."""
    if method not in METHODS:
        raise DataError(f"--method must be one of {', '.join(METHODS)} for calibrate, got {method!r}")
    q = np.asarray(q, dtype=np.float64)
    measured = np.asarray(measured, dtype=np.float64)
    B, X = initial_frames(robot, q, measured, position_only=position_only, estimate_base=estimate_base,
                          estimate_tool=estimate_tool)
    r0 = robot.replace(base=B, tool=np.asarray(robot.tool) @ X)
    J = np.asarray(identification_jacobian(r0, jnp.asarray(q), position_only=position_only, base=True, tool=True))
    J = J.reshape(-1, J.shape[-1])
    names = param_names(robot, base=True, tool=True)
    n4 = 4 * robot.n_joints
    frames = _frame_cols(robot, position_only, estimate_base, estimate_tool)
    union = sorted(set().union(*(c.dh for c in candidates)))
    order = frames + union  # frames first: a DH error a frame absorbs is the one held at 0
    a = analyze(J[:, order], [names[i] for i in order])
    kept = {order[i] for i in a.base}
    free_frames = [i for i in frames if i in kept]
    free_dh = [i for i in union if i in kept]
    fixed_frames = [names[i] for i in frames if i not in kept]
    if fixed_frames:
        raise DataError(f"base/tool parameters {', '.join(fixed_frames)} are not identifiable from these poses; "
                        f"use --no-estimate-base / --no-estimate-tool or more varied poses")
    # how many parameters the candidates need, from a generic (random, seeded) pose set, so too few
    # data poses are refused instead of silently dropping parameters
    from .simulate import sample_poses

    qg = sample_poses(jax.random.PRNGKey(0), robot, (max(60, len(q)),))
    Jg = np.asarray(identification_jacobian(r0, qg, position_only=position_only, base=True, tool=True))
    n_need = analyze(Jg.reshape(-1, Jg.shape[-1])[:, order], [names[i] for i in order]).rank + n_params(camera)
    rpp = 3 if position_only else 6
    if len(q) * rpp < n_need:
        raise DataError(f"too few poses: {len(q)} poses x {rpp} rows = {len(q) * rpp} equations "
                        f"for {n_need} parameters; need at least {-(-n_need // rpp)} poses")
    # identifiability report over all DH errors (same ordering rule), for the JSON report
    all_order = frames + list(range(n4))
    ident = analyze(J[:, all_order], [names[i] for i in all_order])
    free = tuple(free_dh) + tuple(free_frames)
    return Setup(robot=robot, q=q, measured=measured, position_only=position_only, estimate_base=estimate_base,
                 estimate_tool=estimate_tool, method=method, candidates=tuple(candidates), ident=ident, free=free,
                 n_dh_free=len(free_dh), n_needed=n_need, max_steps=max_steps, camera=camera)


def _prior_vector(setup: Setup, cand: Candidate | None) -> np.ndarray:
    """Prior weight of each free DH error for a candidate (None = frames only)."""
    out = np.full(setup.n_dh_free, PIN)
    if cand is None:
        return out
    for j, i in enumerate(setup.free[:setup.n_dh_free]):
        if i in cand.dh:
            out[j] = cand.prior_weight(i)
    return out


def _problem(setup: Setup) -> Problem:
    return Problem(template=setup.robot, free=setup.free, n_dh_free=setup.n_dh_free,
                    rows=3 if setup.position_only else 6, camera=setup.camera)


def _sigmas(err, mask, position_only):
    """RMS per coordinate (mm) and per axis (rad) of pose errors ``(K, 6)`` over ``mask``."""
    n = 3 * mask.sum()
    sp = np.sqrt(np.sum(mask[:, None] * err[:, :3] ** 2) / n)
    sr = 1.0 if position_only else np.sqrt(np.sum(mask[:, None] * err[:, 3:] ** 2) / n)
    return max(sp, 1e-6), max(sr, 1e-9)


def _weights(sig):
    return np.c_[np.repeat(1 / sig[:, :1], 3, 1), np.repeat(1 / sig[:, 1:], 3, 1)]


def fit_many(setup: Setup, train_masks: np.ndarray, candidates) -> dict:
    """Fit frames only and every candidate on every training mask ``(S, K)`` in two vmapped
    calls: (A) frames only with unit weights (1 mm, 1 deg), whose training residual gives each
    mask's ``sigma_pos, sigma_rot``; (B) every candidate from the frames-only solution with
    those weights.

    **Returns** a dict: ``frames`` (dict of the stage-A fit: ``delta, B, X, ok, steps, pred``,
    leading axis S), and the stage-B arrays with leading axes ``(S, C)``: ``delta (n, 4)``,
    ``B``, ``X``, ``ok``, ``steps``, ``pred (K, 4, 4)``, ``camera (m,)`` (the camera unknowns);
    ``sigmas (S, 2)``.
    """
    train_masks = np.atleast_2d(np.asarray(train_masks, dtype=bool))
    S, K = train_masks.shape
    C = len(candidates)
    n = setup.robot.n_joints
    tool0 = np.asarray(setup.robot.tool)
    B0 = np.empty((S, 4, 4))
    X0 = np.empty((S, 4, 4))
    for s in range(S):
        tr = train_masks[s]
        B, X = initial_frames(setup.robot, setup.q[tr], setup.measured[tr], position_only=setup.position_only,
                              estimate_base=setup.estimate_base, estimate_tool=setup.estimate_tool)
        B0[s], X0[s] = B, tool0 @ X
    mask = train_masks.astype(np.float64)
    q, meas = jnp.asarray(setup.q), jnp.asarray(setup.measured)
    w0 = _weights(np.tile([1.0, np.radians(1.0)], (S, 1)))
    m = n_params(setup.camera)

    def camera_prior(cand):
        """Free: the candidate's camera model's unknowns, a prefix of the setup's (nested models,
        jaxcal.camera); held at 0: the rest, and all of them in the frames-only stage (None)."""
        k = 0 if cand is None else n_params(cand.camera)
        return [0.0] * k + [PIN] * (m - k)

    prior0 = np.tile(np.r_[_prior_vector(setup, None), camera_prior(None)], (S, 1))
    fit_a = _fitter(setup, "lm" if setup.method == "linear" else setup.method)
    (da, Ba, Xa, _), oka, sta, Ta = fit_a(jnp.zeros((S, n, 4)), jnp.asarray(B0), jnp.asarray(X0), q, meas,
                                       jnp.asarray(mask), jnp.asarray(w0), jnp.asarray(prior0))
    ea = np.asarray(pose_error(meas[None], Ta))
    sig = np.array([_sigmas(ea[s], mask[s], setup.position_only) for s in range(S)])
    rep = lambda a: np.repeat(np.asarray(a)[:, None], C, axis=1).reshape((S * C,) + np.shape(a)[1:])
    prior = np.tile(np.stack([np.r_[_prior_vector(setup, c), camera_prior(c)] for c in candidates]), (S, 1))
    (d, B, X, dsc), ok, st, T = _fitter(setup, setup.method)(
        jnp.asarray(rep(da)), jnp.asarray(rep(Ba)), jnp.asarray(rep(Xa)), q, meas, jnp.asarray(rep(mask)),
        jnp.asarray(rep(_weights(sig))), jnp.asarray(prior))
    sh = lambda a: np.asarray(a).reshape((S, C) + np.shape(a)[1:])
    return {"frames": {"delta": np.asarray(da), "B": np.asarray(Ba), "X": np.asarray(Xa), "ok": np.asarray(oka),
                       "steps": np.asarray(sta), "pred": np.asarray(Ta)},
            "delta": sh(d), "B": sh(B), "X": sh(X), "ok": sh(ok), "steps": sh(st), "pred": sh(T),
            "B_init": B0, "X_init": X0, "sigmas": sig, "camera": sh(dsc)}
