r"""The measurement model: what a sensor reports as a function of the calibration parameters,
its residual, and the residual's exact Jacobian.

A calibration estimates a :class:`Model`: the robot (DH table or joint frames, base and tool
frames), the positions of the measured points on the tool, and the unknowns of a camera model.
What is measured per pose is one of

* the **tool's pose** (``n_points = 0``): 6 residual rows ``[p_m - p, log(R_m R^T)]`` (mm, rad),
  optionally through a camera model (:mod:`jaxcal.camera`);
* **points** fixed to the tool (``n_points = M >= 1``, e.g. a laser tracker's reflector, or the
  markers of a motion-capture rigid body): ``3 M`` rows ``p_m,j - p_j`` (mm). A point not seen
  at a pose (an occluded marker) is NaN in the measurements: its rows are not observed
  (:func:`observed`) and weigh nothing in a fit; its errors come out NaN.

The parameters ``x`` are laid out by a :class:`Layout`::

    x = [kinematic errors (4n DH, or 7n joint-frame), base twist (6, if estimated),
         tool: a twist (6) for poses, a translation (3) per point for points (if estimated),
         camera unknowns]

``x`` is relative to a reference model: a frame moves by a translation and turns by a rotation
vector (:func:`jaxcal.error_model.perturb`), the points move by ``dm_j`` in the tool frame.
:func:`residual_and_jacobian` returns the exact derivative ``d e / d x`` (the frames' rotations
through the Jacobians of SO(3)'s exponential, the rotation residual through the inverse right
Jacobian), built from the analytic identification Jacobian of eq. (10); nothing is
differentiated through the kinematics.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .camera import apply_camera, camera_jacobian
from .camera import n_params as camera_size
from .camera import param_names as camera_names
from .error_model import FRAME_NAMES, dh_column_entries, perturb, pose_error, stack_columns
from .kinematics import deflected, fk, moments_from_ref
from .lie import make_transform, so3_exp, so3_left_jacobian, so3_right_jacobian_inv
from .robot import Robot


@dataclasses.dataclass(frozen=True)
class Layout:
    """Which parameters a fit carries and what is measured (hashable: a static argument)."""

    kin_names: tuple[str, ...]
    """Names of the kinematic errors (DH or joint-frame), in order."""
    base: bool = False
    """Estimate the base frame (measurement frame -> robot base): 6 twist parameters."""
    tool: bool = False
    """Estimate the tool: a twist (6) for poses, a translation (3) per point for points."""
    n_points: int = 0
    """0: the tool frame's pose is measured; M >= 1: M points on the tool are measured."""
    camera: str = "none"
    """Camera measurement model (:mod:`jaxcal.camera`) of pose data."""

    kin_units: tuple[str, ...] = ()
    """Unit of each kinematic error (``mm`` or ``rad``); empty: from the DH names."""
    n_comp: int = 0
    """Joint compliances carried (one per joint, :attr:`jaxcal.Robot.compliance`), or 0."""
    point_numbers: tuple[int, ...] = dataclasses.field(default=(), compare=False, repr=False)
    """The data file's number of each measured point, for their parameters' names (empty: 1..M);
    no part of the computation, so not of the layout's identity or printed key (one program)."""

    @classmethod
    def of(
        cls,
        robot: Robot,
        *,
        base: bool = False,
        tool: bool = False,
        n_points: int = 0,
        camera: str = "none",
        compliance: bool = False,
        point_numbers: tuple[int, ...] = (),
    ) -> "Layout":
        names, units = tuple(robot.param_names()), tuple(robot.param_units())
        n_comp = robot.n_joints if compliance else 0
        return cls(names, bool(base), bool(tool), int(n_points), camera, units, n_comp, tuple(point_numbers))

    @property
    def n_kin(self) -> int:
        return len(self.kin_names)

    @property
    def n_tool(self) -> int:
        return 0 if not self.tool else 6 if self.n_points == 0 else 3 * self.n_points

    @property
    def n_camera(self) -> int:
        return camera_size(self.camera)

    @property
    def size(self) -> int:
        return self.n_kin + 6 * self.base + self.n_tool + self.n_comp + self.n_camera

    @property
    def rows(self) -> int:
        """Residual rows per pose."""
        return 6 if self.n_points == 0 else 3 * self.n_points

    @property
    def frames(self) -> tuple[int, ...]:
        """Indices of the base and tool parameters."""
        return tuple(range(self.n_kin, self.n_kin + 6 * self.base + self.n_tool))

    @property
    def compliances(self) -> tuple[int, ...]:
        """Indices of the joint compliances (after the frames, before the camera)."""
        start = self.n_kin + 6 * self.base + self.n_tool
        return tuple(range(start, start + self.n_comp))

    @property
    def cameras(self) -> tuple[int, ...]:
        return tuple(range(self.size - self.n_camera, self.size))

    def names(self) -> list[str]:
        out = list(self.kin_names)
        out += [f"base_{c}" for c in FRAME_NAMES] if self.base else []
        if self.tool:
            if self.n_points == 0:
                out += [f"tool_{c}" for c in FRAME_NAMES]
            elif self.n_points == 1:
                out += ["tool_x", "tool_y", "tool_z"]
            else:
                numbers = self.point_numbers or range(1, self.n_points + 1)
                out += [f"point{j}_{c}" for j in numbers for c in "xyz"]
        out += [f"compliance{j + 1}" for j in range(self.n_comp)]
        return out + camera_names(self.camera)

    def units(self) -> list[str]:
        """Unit of each parameter: mm or rad (compliances rad/mm; camera unknowns are
        dimensionless, ``1``)."""
        kin = list(self.kin_units) or ["rad" if n.startswith(("theta", "alpha")) else "mm" for n in self.kin_names]
        frame = ["mm"] * 3 + ["rad"] * 3
        tool = (frame if self.n_points == 0 else ["mm"] * (3 * self.n_points)) if self.tool else []
        return kin + (frame if self.base else []) + tool + ["rad/mm"] * self.n_comp + ["1"] * self.n_camera


class Model(eqx.Module):
    """A calibrated (or nominal) model: the robot, the measured points on its tool, and the
    camera model's unknowns."""

    robot: Robot
    points: Float[Array, "M 3"]
    """Measured points in the tool frame (``(0, 3)``: the tool frame's pose is measured)."""
    camera_params: Float[Array, " c"]
    camera: str = eqx.field(static=True, default="none")

    def __init__(self, robot: Robot, points=None, camera_params=None, camera: str = "none"):
        self.robot = robot
        # a copy: jnp.asarray may alias the caller's NumPy buffer (as_f64)
        self.points = jnp.zeros((0, 3)) if points is None else jnp.array(points, jnp.float64).reshape(-1, 3)
        self.camera = camera
        c = jnp.asarray(np.zeros(camera_size(camera)) if camera_params is None else camera_params, jnp.float64)
        self.camera_params = c.reshape(camera_size(camera))

    @property
    def n_points(self) -> int:
        return self.points.shape[0]


def measured_robot(model: Model) -> Robot:
    """The robot whose tool frame sits at the measured point (for one point; the robot itself for
    poses or several points), so that its forward kinematics gives what was measured: the robot
    a controller should load."""
    if model.n_points != 1:
        return model.robot
    robot = model.robot
    c = robot.compliance
    if c is not None and (isinstance(c, jax.core.Tracer) or np.any(np.asarray(c) != 0)):  # the weight stays put
        load = (jnp.zeros(3) if robot.load is None else robot.load) - model.points[0]
        robot = eqx.tree_at(lambda r: r.load, robot, load, is_leaf=lambda v: v is None)
    if isinstance(model.points, jax.core.Tracer) or isinstance(robot.tool, jax.core.Tracer):
        offset = jnp.eye(4).at[:3, 3].set(model.points[0])
        return eqx.tree_at(lambda r: r.tool, robot, robot.tool @ offset)
    tool = np.array(robot.tool)  # NumPy: eager JAX operations would each compile
    tool[:3, 3] += tool[:3, :3] @ np.asarray(model.points)[0]
    return eqx.tree_at(lambda r: r.tool, robot, jnp.asarray(tool, jnp.float64))


def apply(model: Model, layout: Layout, x: Float[Array, " m"]) -> Model:
    """The model with parameter errors ``x`` applied (exactly)."""
    k = layout.n_kin + 6 * layout.base
    pose_tool = layout.tool and layout.n_points == 0
    robot = perturb(model.robot, x[: k + 6 * pose_tool], base=layout.base, tool=pose_tool)
    points = model.points
    if layout.tool and layout.n_points:
        points = points + x[k : k + layout.n_tool].reshape(points.shape)
    if layout.n_comp:  # a rigid robot starts from zero compliance
        c0 = jnp.zeros(layout.n_comp) if robot.compliance is None else robot.compliance
        c = c0 + x[layout.compliances[0] : layout.compliances[0] + layout.n_comp]
        robot = eqx.tree_at(lambda r: r.compliance, robot, c, is_leaf=lambda v: v is None)
    cam = model.camera_params
    if layout.n_camera:
        cam = cam + x[layout.size - layout.n_camera :]
    return eqx.tree_at(lambda m: (m.robot, m.points, m.camera_params), model, (robot, points, cam))


def predict(model: Model, q: Float[Array, "K n"]):
    """What is measured at joint values ``q``: tool poses ``(K, 4, 4)`` (through the camera
    model) or points ``(K, M, 3)``."""
    T = fk(model.robot, q)
    if model.n_points == 0:
        return apply_camera(T, model.camera_params, model.camera)
    return jnp.einsum("kij,mj->kmi", T[..., :3, :3], model.points) + T[..., None, :3, 3]


def errors(model: Model, q, target) -> Float[Array, "K rows"]:
    """Residual rows ``measured - predicted`` per pose (see the module docstring)."""
    pred = predict(model, q)
    if model.n_points == 0:
        return pose_error(target, pred)
    return (target - pred).reshape(target.shape[0], -1)


def observed(target) -> Bool[Array, "*K rows"]:
    """Which residual rows of each pose (any leading axes) were measured: all of a pose's; a
    point's three unless it is NaN (lost at that pose). NumPy in, NumPy out; traceable."""
    xp = np if isinstance(target, np.ndarray) else jnp
    lead = target.shape[:-2]
    if target.shape[-2:] == (4, 4):
        return xp.ones(lead + (6,), bool)
    return xp.isfinite(target).reshape(lead + (-1,))


def filled(target):
    """``target`` with its lost (NaN) coordinates set to 0, for a fit that gives them no weight."""
    xp = np if isinstance(target, np.ndarray) else jnp
    return xp.where(xp.isfinite(target), target, 0.0)


def _times(A, C):
    """``A @ C`` for a block ``A (3, 3, K)`` (pose axis last) and a constant ``C (3, 3)``, as
    broadcast multiply-adds (elementwise over poses, so XLA fuses them)."""
    return sum(A[:, j : j + 1, :] * C[j][None, :, None] for j in range(3))


def _cross(u, d):
    """``u x d`` for a constant ``u (3,)`` and ``d (3, K)``: three ``(K,)`` entries."""
    return [u[1] * d[2] - u[2] * d[1], u[2] * d[0] - u[0] * d[2], u[0] * d[1] - u[1] * d[0]]


def _columns(cols, K):
    """Columns given entry by entry (each a list of row entries: arrays broadcastable to ``(K,)``
    or Python floats) as ``(p, rows, K)``, in one stack."""
    return jnp.stack([jnp.stack([jnp.broadcast_to(jnp.asarray(e, jnp.float64), (K,)) for e in col]) for col in cols])


def residual_and_jacobian_soa(model: Model, layout: Layout, x: Float[Array, " m"], q: Float[Array, "K n"], target):
    """:func:`residual_and_jacobian` with the pose axis last: ``e (rows, K)`` and ``J (m, rows,
    K)``. Every column is an elementwise expression over the poses, stacked once
    (:func:`jaxcal.error_model.dh_column_entries`)."""
    cur = apply(model, layout, x)
    robot = cur.robot
    K, n = q.shape[0], robot.n_joints
    k = layout.n_kin + 6 * layout.base
    pts = jnp.zeros((1, 3)) if layout.n_points == 0 else cur.points
    q_eff = deflected(robot, q)  # every column at the joint values the arm reaches
    P, W, R, p_e, p_pts = dh_column_entries(robot, q_eff, pts)  # entries; (3, 3, K), (3, K), (M, 3, K)
    M = max(layout.n_points, 1)
    # the frames' columns: each a list of rows, a point's 3 position rows then (poses) 3 rotation rows
    frames = []
    if layout.base:
        # the base moves by v and turns by exp(w) about its origin t_B: a point p moves by
        # dv + u x (p - t_B) for u = J_l(w) dw, and (poses) the tool turns by u
        J_l = so3_left_jacobian(x[layout.n_kin + 3 : layout.n_kin + 6])
        lev = [p - robot.base[:3, 3, None] for p in p_pts]
        for c in range(3):
            e_c = [1.0 if r == c else 0.0 for r in range(3)]
            frames.append(e_c * M + ([0.0] * 3 if layout.n_points == 0 else []))
        for c in range(3):
            u = J_l[:, c]
            frames.append(sum((_cross(u, d) for d in lev), []) + (list(u) if layout.n_points == 0 else []))
    if layout.tool and layout.n_points == 0:  # X = X0 [exp(w) | v]: the origin moves by R0 dv, turns by R J_r dw
        w = x[k + 3 : k + 6]
        R0 = _times(R, so3_exp(w).T)
        Rr = _times(R, so3_left_jacobian(w).T)
        frames += [[R0[r, c] for r in range(3)] + [0.0] * 3 for c in range(3)]
        frames += [[0.0] * 3 + [Rr[r, c] for r in range(3)] for c in range(3)]
    if layout.tool and layout.n_points:  # dp_j / dm_j = R
        frames += [[R[r, c] if i == j else 0.0 for i in range(M) for r in range(3)] for j in range(M) for c in range(3)]
    if layout.n_comp:  # a compliance turns its joint by tau: the joint offset's column times tau
        tau = moments_from_ref(robot, q).T  # (n, K)
        rows0 = sum(P[0], []) + (list(W[0]) if layout.n_points == 0 else [])
        frames += [[jnp.broadcast_to(e, (n, K))[j] * tau[j] for e in rows0] for j in range(n)]
    if layout.n_points:
        kinds = range(robot.n_kinds)
        J = stack_columns([sum(P[kk], []) for kk in kinds], n, K)  # (p n, 3M, K)
        if frames:
            J = jnp.concatenate([J, _columns(frames, K)], 0)
        e = (target - jnp.moveaxis(p_pts, -1, 0)).reshape(K, 3 * M)
        return e.T, -J
    T = make_transform(jnp.moveaxis(R, -1, 0), p_e.T)
    e = pose_error(target, apply_camera(T, cur.camera_params, layout.camera))  # (K, 6)
    A = jnp.moveaxis(so3_right_jacobian_inv(e[:, 3:]), 0, -1)  # (3, 3, K)

    def finish(rows):  # -[dp; Jr^-1(phi) w]: the residual's derivative
        out = [-r for r in rows[:3]]
        return out + [-sum(A[i, j] * rows[3 + j] for j in range(3)) for i in range(3)]

    if layout.camera == "none":
        J = stack_columns([finish(P[kk][0] + W[kk]) for kk in range(robot.n_kinds)], n, K)  # (p n, 6, K)
        if frames:
            J = jnp.concatenate([J, _columns([finish(col) for col in frames], K)], 0)
        return e.T, J
    # a camera's columns come per pose (not a hot path): dense, then the same residual derivative
    J = stack_columns([P[kk][0] + W[kk] for kk in range(robot.n_kinds)], n, K)
    if frames:
        J = jnp.concatenate([J, _columns(frames, K)], 0)
    J = jnp.moveaxis(camera_jacobian(jnp.moveaxis(J, -1, 0).swapaxes(1, 2), T, cur.camera_params, layout.camera), 0, -1)
    rows = [J[r] for r in range(6)]  # each (m, K)
    return e.T, jnp.stack(finish(rows), 1)


def residual_and_jacobian(model: Model, layout: Layout, x: Float[Array, " m"], q: Float[Array, "K n"], target):
    """``(e, J)``: the residual rows ``e (K, rows)`` of the model with ``x`` applied and their
    exact derivative ``J = d e / d x (K, rows, m)`` (module docstring)."""
    e, J = residual_and_jacobian_soa(model, layout, x, q, target)
    return e.T, jnp.moveaxis(J, -1, 0).swapaxes(1, 2)


def jacobian(model: Model, layout: Layout, q: Float[Array, "K n"]) -> Float[Array, "K rows m"]:
    """The Jacobian of the predicted measurements with respect to ``x`` at ``x = 0`` (the
    identification Jacobian of this measurement model): what identifiability, the Cramér–Rao
    bound and pose design are computed from. Pure; jit it."""
    return -residual_and_jacobian(model, layout, jnp.zeros(layout.size), q, predict(model, q))[1]


def row_weights(layout: Layout, sigma_pos, sigma_rot) -> Float[Array, " rows"]:
    """``1 / sigma`` per residual row of a pose: position rows ``1/sigma_pos`` (mm), rotation rows
    ``1/sigma_rot`` (rad)."""
    sp, sr = jnp.asarray(sigma_pos, jnp.float64), jnp.asarray(sigma_rot, jnp.float64)
    if layout.n_points == 0:
        return jnp.concatenate([jnp.full(3, 1.0) / sp, jnp.full(3, 1.0) / sr])
    return jnp.full(3 * layout.n_points, 1.0) / sp


def check_layout(model: Model, layout: Layout) -> None:
    """Raise ``ValueError`` when a model and a layout do not describe the same measurement."""
    if model.n_points != layout.n_points or model.camera != layout.camera:
        raise ValueError(
            f"model measures {model.n_points} points with camera {model.camera!r}, the layout "
            f"{layout.n_points} points with camera {layout.camera!r}"
        )
    if len(layout.kin_names) != model.robot.n_kinds * model.robot.n_joints:
        raise ValueError("layout is for another robot")


def load_model(path, *, base_link: str | None = None, tip_link: str | None = None) -> Model:
    """A saved model (:func:`save_model`): the robot with its frames and the measured points on
    its tool. A robot file without points is a model whose tool frame's origin is measured."""
    from .robot import read_robot_file

    robot, points = read_robot_file(path, base_link=base_link, tip_link=tip_link)
    return Model(robot, points)


def model_points(model: "Model", recorded, chosen, *, option: str = "points") -> "Model":
    """``model`` with only its points that the data file numbers ``chosen``, ``recorded`` being
    the file's number of each of its points (:func:`jaxcal.robot.read_point_numbers`; None:
    1..M). A number it was not fitted on is a :class:`jaxcal.DataError` naming ``option``."""
    from .errors import DataError

    recorded = list(range(1, model.n_points + 1)) if recorded is None else list(recorded)
    missing = [j for j in chosen if j not in recorded]
    if missing:
        raise DataError(
            f"{option} {','.join(map(str, missing))}: the model was fitted on the data file's point(s) "
            f"{', '.join(map(str, recorded))} only",
            option=option,
        )
    keep = [recorded.index(j) for j in chosen]
    return Model(model.robot, np.asarray(model.points)[keep], model.camera_params, camera=model.camera)


def save_model(
    model: Model,
    path,
    *,
    comment: dict | None = None,
    template=None,
    base_link=None,
    tip_link=None,
    training_ranges: dict | None = None,
    point_numbers=None,
):
    """Write a model atomically: a URDF (``.urdf``, joint-frame robots; ``template`` the nominal
    URDF whose other links it keeps) or a TOML robot file, with the measured points and the
    ``training_ranges`` it was fitted on (:func:`jaxcal.robot.read_training_ranges`), and the
    points' ``point_numbers`` in the data file (:func:`jaxcal.robot.read_point_numbers`). The camera
    model's unknowns are a sensor's, not the robot's, and are not written."""
    from .robot import save_robot

    pts = np.asarray(model.points) if model.n_points else None
    save_robot(
        model.robot, path, comment=comment, points=pts, template=template, base_link=base_link, tip_link=tip_link,
        training_ranges=training_ranges, point_numbers=point_numbers,
    )  # fmt: skip
