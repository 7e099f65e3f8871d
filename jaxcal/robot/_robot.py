"""The robot model: a DH table, or joint frames as a URDF gives them, as an equinox Module, with
base and tool frames.

Units inside jaxcal are millimetres and radians; the file readers convert at the edges and
remember the file's units, so data files and written models follow them.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import as_f64
from ..errors import RobotFileError

CONVENTIONS = ("sdh", "mdh", "joint")
LENGTH_UNITS = {"mm": 1.0, "m": 1000.0}
ANGLE_UNITS = {"rad": 1.0, "deg": np.pi / 180.0}
JOINT_TYPES = ("R", "P")
DEFAULT_LIMITS = {"R": (-np.pi, np.pi), "P": (-1000.0, 1000.0)}
"""Limits (rad, mm) of a joint given none: a turn either way, a metre either way."""
DH_NAMES = ("theta", "d", "a", "alpha")
JOINT_FRAME_NAMES = ("offset", "x", "y", "z", "rx", "ry", "rz")
"""Per-joint parameters of the joint-frame form: the joint offset, then a rigid correction of
the joint's origin (a translation and a rotation vector, in the origin's own axes)."""


class Robot(eqx.Module):
    """A serial arm described by a Denavit–Hartenberg table or by joint frames.

    With ``convention="sdh"`` (standard DH, the paper's eq. 1) link ``i`` is
    ``Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``; with ``"mdh"`` (modified DH, Craig) it is
    ``Rx(alpha_i) Tx(a_i) Rz(theta_i) Tz(d_i)``, where row ``i`` stores Craig's
    ``alpha_{i-1}, a_{i-1}``. A revolute joint adds ``q_i`` to ``theta_i``, a prismatic one to
    ``d_i``. The end pose is ``base @ A_1 ... A_n @ tool``.

    With ``convention="joint"`` (a URDF chain) link ``i`` is ``O_i E_i M_i(q_i + offset_i)``:
    the joint's fixed origin ``O_i`` (``origins``), a rigid correction ``E_i = [exp(r_i) | t_i]``
    and the joint's motion ``M_i``, a turn about (revolute) or a shift along (prismatic) the unit
    ``axes[i]``. The parameter table ``dh`` then holds ``(offset, x, y, z, rx, ry, rz)`` per joint
    (:data:`JOINT_FRAME_NAMES`), zero for the nominal robot. Every joint has its own frame, so
    nearly parallel axes are no singularity, unlike DH (Hayati's problem).
    """

    dh: Float[Array, "n p"]
    """Per joint ``(theta offset, d, a, alpha)`` in mm and rad, base to tip (DH); the joint-frame
    parameters :data:`JOINT_FRAME_NAMES` (``convention="joint"``)."""
    base: Float[Array, "4 4"]
    """Measurement (world) frame -> robot base frame 0."""
    tool: Float[Array, "4 4"]
    """Last joint frame (flange) -> tool point/frame."""
    q_limits: Float[Array, "n 2"]
    """Joint limits ``[lower, upper]`` (rad, or mm for prismatic joints; :data:`DEFAULT_LIMITS` when
    none are given): poses are drawn and commands checked within them."""
    origins: Float[Array, "n 4 4"] | None = None
    """Joint frames only: each joint's fixed origin in its parent's frame (the fixed joints
    before it folded in)."""
    axes: Float[Array, "n 3"] | None = None
    """Joint frames only: each joint's unit axis in its origin frame."""
    compliance: Float[Array, " n"] | None = None
    """Joint compliance (rad per mm), or ``None`` for a rigid arm: a revolute joint turns by
    ``compliance_i * tau_i(q)`` beyond its command, ``tau_i`` the gravity moment arm (mm) about its
    axis of a unit weight at the tool origin (:func:`jaxcal.kinematics.gravity_moments`); 0 for
    prismatic joints."""
    moment_ref: Float[Array, " n"] | None = None
    """The gravity moment arms (mm) at which the joint offsets hold as written: a compliant joint
    turns by ``compliance_i * (tau_i(q) - moment_ref_i)``. A calibration sets them to the mean over
    its poses, so that the rigid geometry, which readers other than jaxcal load, is the arm at its
    typical load rather than weightless. ``None``: zero (the weightless arm)."""
    load: Float[Array, " 3"] | None = None
    """Where that unit weight sits, in the tool frame (mm), when not at the tool origin: a
    measured point folded into the tool (:func:`jaxcal.model.measured_robot`) moves the tool, not
    the weight the compliances were fitted with. ``None``: the tool origin."""
    convention: str = eqx.field(static=True)
    joint_types: tuple[str, ...] = eqx.field(static=True)
    name: str = eqx.field(static=True, default="robot")
    joint_names: tuple[str, ...] = eqx.field(static=True, default=())
    """Names of the joints (data columns may use them); ``q1..qn`` unless the file names them."""
    units: tuple[str, str] = eqx.field(static=True, default=("mm", "rad"))
    """``(length, angle)`` units of the file the robot came from: data files are read in them
    unless told otherwise, and a calibrated robot is written in them."""
    limits_set: tuple[bool, ...] | None = eqx.field(static=True, default=None)
    """Which joints' limits the file (or caller) gave: a joint given exactly the defaults (a xacro
    ``${pi}``) has them, one given none does not. ``None``: those other than the defaults."""

    def __init__(
        self,
        dh,
        *,
        convention="sdh",
        joint_types=None,
        base=None,
        tool=None,
        q_limits=None,
        name="robot",
        joint_names=None,
        units=("mm", "rad"),
        origins=None,
        axes=None,
        compliance=None,
        load=None,
        limits_set=None,
        moment_ref=None,
    ):
        if convention not in CONVENTIONS:
            raise RobotFileError(f"convention must be one of {CONVENTIONS}, got {convention!r}")
        kinds = JOINT_FRAME_NAMES if convention == "joint" else DH_NAMES
        if dh is None and convention == "joint" and origins is not None:
            dh = np.zeros((np.shape(origins)[0], len(kinds)))
        dh = as_f64(dh, "dh")
        if dh.ndim != 2 or dh.shape[1] != len(kinds):
            raise RobotFileError(f"dh must have shape (n_joints, {len(kinds)}) = {kinds}, got {dh.shape}")
        n = dh.shape[0]
        if n < 1:
            raise RobotFileError("a robot needs at least one joint")
        bad = ~np.isfinite(np.asarray(dh))
        if bad.any():
            j, k = np.argwhere(bad)[0]
            raise RobotFileError(f"joint {j + 1}: {kinds[k]} is not finite")
        self.origins, self.axes = _joint_frames(convention, origins, axes, n)
        joint_types = tuple(str(t) for t in joint_types) if joint_types is not None else ("R",) * n
        if len(joint_types) != n:
            raise RobotFileError(f"{len(joint_types)} joint types for {n} joints")
        for i, t in enumerate(joint_types):
            if t not in JOINT_TYPES:
                raise RobotFileError(f"joint {i + 1}: type must be 'R' or 'P', got {t!r}")
        self.dh = dh
        self.base = _check_transform(base, "base")
        self.tool = _check_transform(tool, "tool")
        if q_limits is None:
            q_limits = np.array([DEFAULT_LIMITS[t] for t in joint_types])
        q_limits = as_f64(q_limits, "q_limits")
        if q_limits.shape != (n, 2):
            raise RobotFileError(f"q_limits must have shape ({n}, 2), got {q_limits.shape}")
        lim = np.asarray(q_limits)  # NumPy: an eager JAX comparison would compile for every new robot
        if not np.all(lim[:, 0] < lim[:, 1]):
            j = int(np.argmin(lim[:, 1] - lim[:, 0]))
            raise RobotFileError(f"joint {j + 1}: lower limit is not below the upper limit")
        self.q_limits = q_limits
        if limits_set is not None:
            limits_set = tuple(bool(v) for v in limits_set)
            if len(limits_set) != n:
                raise RobotFileError(f"limits_set must say for each of the {n} joints whether limits were given")
        self.limits_set = limits_set
        self.compliance = _check_compliance(compliance, joint_types)
        self.moment_ref = _check_moment_ref(moment_ref, joint_types)
        self.load = None if load is None else as_f64(load, "load")
        if self.load is not None and (self.load.shape != (3,) or not np.all(np.isfinite(np.asarray(self.load)))):
            raise RobotFileError(f"load must be 3 finite numbers (mm, tool frame), got {np.asarray(load)!r}")
        self.convention = convention
        self.joint_types = joint_types
        self.name = str(name)
        joint_names = tuple(f"q{i + 1}" for i in range(n)) if joint_names is None else tuple(map(str, joint_names))
        if len(joint_names) != n or len(set(joint_names)) != n:
            raise RobotFileError(f"joint_names must be {n} distinct names, got {joint_names}")
        self.joint_names = joint_names
        units = tuple(units)
        if len(units) != 2 or units[0] not in LENGTH_UNITS or units[1] not in ANGLE_UNITS:
            raise RobotFileError(
                f"units must be (length, angle) with length in {list(LENGTH_UNITS)} and angle "
                f"in {list(ANGLE_UNITS)}, got {units}"
            )
        self.units = units

    # -- views --------------------------------------------------------------------------
    @property
    def n_joints(self) -> int:
        return self.dh.shape[-2]

    @property
    def theta(self):
        return self.dh[..., 0]

    @property
    def d(self):
        return self.dh[..., 1]

    @property
    def a(self):
        return self.dh[..., 2]

    @property
    def alpha(self):
        return self.dh[..., 3]

    @property
    def n_kinds(self) -> int:
        """Parameters per joint: 4 (DH) or 7 (joint frames)."""
        return len(JOINT_FRAME_NAMES if self.convention == "joint" else DH_NAMES)

    @property
    def revolute_mask(self) -> Float[Array, " n"]:
        return jnp.array([t == "R" for t in self.joint_types], dtype=jnp.float64)

    def limits_given(self) -> np.ndarray:
        """``(n,)`` False for a joint given no limits (a URDF ``continuous`` joint without both
        bounds, a file without them): its :data:`DEFAULT_LIMITS` are a range to draw poses in, not
        the arm's. Without :attr:`limits_set`, a joint whose limits are those defaults."""
        if self.limits_set is not None:
            return np.array(self.limits_set, dtype=bool)
        lim = np.asarray(self.q_limits)
        default = np.array([DEFAULT_LIMITS[t] for t in self.joint_types])
        return ~np.all(np.abs(lim - default) < 1e-12, axis=1)

    def joint_scale(self) -> np.ndarray:
        """``(n,)`` mm or rad per unit of the robot file, per joint (its length unit for a
        prismatic joint, its angle unit for a revolute one): a joint value in the file's units is
        ``q / joint_scale()``."""
        lu, au = LENGTH_UNITS[self.units[0]], ANGLE_UNITS[self.units[1]]
        return np.array([au if t == "R" else lu for t in self.joint_types])

    def reach(self, q=None) -> float:
        """A rough size of the arm in mm: the DH lengths, the tool offset and the prismatic
        strokes added up (the scale that judges residuals and parameter changes). A stroke is
        the joint's limits, or with joint values ``q (K, n)`` the span they move it over: a file
        without limits gives a prismatic joint +-1000 mm, which would set the scale."""
        dh = np.asarray(self.dh)
        lim = np.asarray(self.q_limits) if q is None else np.stack([np.min(q, 0), np.max(q, 0)], -1)
        stroke = sum(float(lim[i, 1] - lim[i, 0]) for i, t in enumerate(self.joint_types) if t == "P")
        if self.convention == "joint":
            links = np.linalg.norm(np.asarray(self.origins)[:, :3, 3], axis=-1).sum()
        else:
            links = np.abs(dh[:, 1]).sum() + np.abs(dh[:, 2]).sum()
        return float(links + np.linalg.norm(np.asarray(self.tool)[:3, 3]) + stroke)

    def param_names(self) -> list[str]:
        """Names of the kinematic parameters in the order of :attr:`dh` flattened row-major:
        ``theta1, d1, a1, alpha1, ...`` (DH) or ``offset1, x1, y1, z1, rx1, ry1, rz1, ...``."""
        kinds = JOINT_FRAME_NAMES if self.convention == "joint" else DH_NAMES
        return [f"{p}{i + 1}" for i in range(self.n_joints) for p in kinds]

    def param_units(self) -> list[str]:
        """``"mm"`` or ``"rad"`` for each of :meth:`param_names` (a prismatic joint's offset is a
        length)."""
        if self.convention != "joint":
            return ["rad", "mm", "mm", "rad"] * self.n_joints
        return [u for t in self.joint_types for u in ["rad" if t == "R" else "mm"] + ["mm"] * 3 + ["rad"] * 3]

    def replace(self, **kw) -> "Robot":
        """A validated copy with some fields replaced (never mutates ``self``; not for jit)."""
        args = dict(
            dh=self.dh,
            convention=self.convention,
            joint_types=self.joint_types,
            base=self.base,
            tool=self.tool,
            q_limits=self.q_limits,
            name=self.name,
            joint_names=self.joint_names,
            units=self.units,
            origins=self.origins,
            axes=self.axes,
            compliance=self.compliance,
            moment_ref=self.moment_ref,
            load=self.load,
            # new limits say for themselves whether they are given
            limits_set=None if "q_limits" in kw else self.limits_set,
        )
        args.update(kw)
        return Robot(**args)

    def with_meta(self, name: str = "robot", joint_names=None, units=("mm", "rad"), limits_set=None) -> "Robot":
        """The same kinematics (arrays untouched, any leading batch axes kept) with other
        descriptive fields, without validating again. Compiled functions are specialised on
        the static fields: stripping the description lets robots of one structure share them."""
        new = object.__new__(Robot)
        for f in (
            "dh",
            "base",
            "tool",
            "q_limits",
            "origins",
            "axes",
            "compliance",
            "moment_ref",
            "load",
            "convention",
            "joint_types",
        ):
            object.__setattr__(new, f, getattr(self, f))
        n = len(self.joint_types)
        object.__setattr__(new, "name", name)
        object.__setattr__(
            new, "joint_names", tuple(f"q{i + 1}" for i in range(n)) if joint_names is None else tuple(joint_names)
        )
        object.__setattr__(new, "units", tuple(units))
        object.__setattr__(new, "limits_set", None if limits_set is None else tuple(limits_set))
        return new

    def stripped(self) -> "Robot":
        """:meth:`with_meta` with the default description: the structure alone."""
        return self.with_meta()

    def with_dh_delta(self, delta: Float[Array, "n 4"]) -> "Robot":
        return eqx.tree_at(lambda r: r.dh, self, self.dh + delta)


def _joint_frames(convention, origins, axes, n):
    """Validated ``(origins, axes)`` of a joint-frame robot; ``(None, None)`` for DH."""
    if convention != "joint":
        if origins is not None or axes is not None:
            raise RobotFileError("origins and axes belong to joint-frame robots (convention='joint')")
        return None, None
    if origins is None or axes is None:
        raise RobotFileError("a joint-frame robot needs origins (n, 4, 4) and axes (n, 3)")
    O = np.asarray(origins, dtype=np.float64)
    if O.shape != (n, 4, 4):
        raise RobotFileError(f"origins must have shape ({n}, 4, 4), got {O.shape}")
    for i in range(n):
        _check_transform(O[i], f"joint {i + 1} origin")
    a = np.asarray(axes, dtype=np.float64)
    if a.shape != (n, 3) or not np.all(np.isfinite(a)):
        raise RobotFileError(f"axes must be {n} finite 3-vectors, got shape {a.shape}")
    norm = np.linalg.norm(a, axis=1)
    if np.any(norm < 1e-9):
        raise RobotFileError(f"joint {int(np.argmin(norm)) + 1}: the axis is zero")
    return jnp.asarray(O), jnp.asarray(a / norm[:, None])


def _check_compliance(c, joint_types):
    """Validated joint compliance (``None``: a rigid arm)."""
    if c is None:
        return None
    c = as_f64(c, "compliance")
    n = len(joint_types)
    if c.shape != (n,):
        raise RobotFileError(f"compliance must have one value per joint ({n}), got shape {c.shape}")
    cn = np.asarray(c)
    for i, t in enumerate(joint_types):
        if not np.isfinite(cn[i]):
            raise RobotFileError(f"joint {i + 1}: compliance is not finite")
        if t == "P" and cn[i] != 0:
            raise RobotFileError(f"joint {i + 1}: a prismatic joint has no compliance (got {cn[i]:g})")
    return c


def _check_moment_ref(m, joint_types):
    """Validated reference moments (``None``: zero)."""
    if m is None:
        return None
    m = as_f64(m, "moment_ref")
    n = len(joint_types)
    if m.shape != (n,):
        raise RobotFileError(f"moment_ref must have one value per joint ({n}), got shape {m.shape}")
    bad = ~np.isfinite(np.asarray(m))
    if bad.any():
        raise RobotFileError(f"joint {int(np.argmax(bad)) + 1}: moment_ref is not finite")
    return m


def _check_transform(T, name):
    if T is None:
        return jnp.asarray(np.eye(4), dtype=jnp.float64)  # a transfer (with its dtype: no copy compiled)
    T = as_f64(T, name)
    if T.shape != (4, 4):
        raise RobotFileError(f"{name} must be a 4x4 transform, got shape {T.shape}")
    Tn = np.asarray(T)
    if not np.all(np.isfinite(Tn)):
        raise RobotFileError(f"{name} transform has non-finite entries")
    R = Tn[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0 or not np.allclose(Tn[3], [0, 0, 0, 1]):
        raise RobotFileError(f"{name} is not a rigid transform (rotation not orthonormal or bottom row not 0 0 0 1)")
    return T
