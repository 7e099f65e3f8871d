"""Whether a fit is a calibration at all, and what mistake in the input it most likely shows.

A converged fit is not a calibration when its residuals or its parameter changes are far beyond
what a geometric calibration produces (:func:`findings`). The thresholds, all options:

- ``max_residual_mm`` (default 1 % of the robot's reach, prismatic strokes as far as the data
  move them): the calibrated position RMS;
- ``max_rotation_deg`` (2 deg): the calibrated rotation RMS, for poses;
- ``max_length_change_mm`` (5 % of the reach): the largest change of a DH length, or of a URDF
  joint origin's shift;
- ``max_angle_change_deg`` (20 deg): the largest change of a DH angle, or of a URDF joint's offset
  or origin turn (offsets are first put in (-180, 180]);
- ``max_camera_change`` (0.1): the largest camera unknown (:mod:`jaxcal.camera`; dimensionless:
  0.1 is a camera whose reported positions are off by 10 %).

A fit whose residual or parameters are not finite (a diverged solve) is never plausible.

Most such fits come from a mistake in the data file, and the likely ones can be tested: the data
are read again as they would be without that mistake (:data:`MISTAKES`: two position columns
swapped, a mirrored axis, a quaternion written x, y, z, w under names w, x, y, z or the reverse,
a quaternion of the inverse rotation (conjugated), two joint columns swapped, the joint order
reversed, degrees read as radians or the reverse, metres read as millimetres or the reverse),
and the frames-only fit (nominal DH, base and tool estimated, all in one batch) is repeated on
each; a DH table is also read in the other convention (standard or modified DH). A mistake
whose correction brings that residual down to a calibration's size is named, with the residual
before and after (:func:`diagnose`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from jaxtyping import Float

from ..measurements import QUATERNION_MISTAKES, rotations_without
from ..model import Layout, Model
from ..robot import Robot
from . import _core as core

MISTAKES = (
    "swapped x, y",
    "swapped x, z",
    "swapped y, z",
    "mirrored x",
    "mirrored y",
    "mirrored z",
    *QUATERNION_MISTAKES,
    "joints reversed",
    "degrees read as radians",
    "radians read as degrees",
    "metres read as millimetres",
    "millimetres read as metres",
    "prismatic joints in metres read as millimetres",
    "prismatic joints in millimetres read as metres",
)
"""The input mistakes :func:`diagnose` tests, besides two adjacent joint columns swapped."""


RESIDUAL_SHARE = 0.01
"""Default ``max_residual_mm``: this share of the robot's reach."""


@dataclasses.dataclass(frozen=True)
class Thresholds:
    """Plausibility limits (module docstring), resolved for one robot."""

    residual_mm: float
    rotation_deg: float
    length_mm: float
    angle_rad: float
    camera: float = 0.1

    @classmethod
    def of(cls, robot: Robot, opts, q=None) -> "Thresholds":
        reach = robot.reach(None if q is None else np.asarray(q).reshape(-1, robot.n_joints))
        return cls(
            residual_mm=opts.max_residual_mm if opts.max_residual_mm is not None else RESIDUAL_SHARE * reach,
            rotation_deg=opts.max_rotation_deg,
            length_mm=opts.max_length_change_mm if opts.max_length_change_mm is not None else 0.05 * reach,
            angle_rad=np.radians(opts.max_angle_change_deg),
            camera=opts.max_camera_change,
        )


def wrap_angle(a):
    """Angles into (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(a), 2 * np.pi)


def findings(stats: dict, x, layout: Layout, limits: Thresholds, *, free=None, se=None) -> list[str]:
    """What makes a fit implausible as a calibration, each with its evidence (empty: plausible).
    ``stats``: residual statistics of the fit; ``x``: its parameters relative to the nominal
    robot (angles already wrapped); ``se``: their standard errors at the solution, where given.
    A parameter whose standard error alone exceeds its limit is not determined by the data: the
    value written would be arbitrary."""
    out = []
    x = np.asarray(x, dtype=np.float64)
    pos, rot = stats["pos_rms_mm"], stats.get("rot_rms_deg")
    if not np.isfinite(pos) or (rot is not None and not np.isfinite(rot)) or not np.all(np.isfinite(x)):
        return ["the fit diverged: its residual or parameters are not finite numbers"]
    if pos > limits.residual_mm:
        out.append(
            f"the position residual is {pos:.4g} mm RMS after calibration, more than "
            f"{limits.residual_mm:.3g} mm (max_residual_mm)"
        )
    if rot is not None and rot > limits.rotation_deg:
        out.append(
            f"the rotation residual is {rot:.3g} deg RMS after calibration, more than "
            f"{limits.rotation_deg:.3g} deg (max_rotation_deg)"
        )
    names, units = layout.names(), layout.units()
    # a URDF joint frame's values too: its base set is exchanged away from near twins, so values
    # beyond the limits write links far from the arm, or fit a mistake (two joint columns swapped)
    kin = [i for i in range(layout.n_kin) if free is None or i in free]
    lengths = [(abs(x[i]), names[i]) for i in kin if units[i] == "mm"]
    angles = [(abs(x[i]), names[i]) for i in kin if units[i] == "rad"]
    if lengths and max(lengths)[0] > limits.length_mm:
        v, n = max(lengths)
        out.append(f"{n} changes by {v:.4g} mm, more than {limits.length_mm:.3g} mm (max_length_change_mm)")
    if angles and max(angles)[0] > limits.angle_rad:
        v, n = max(angles)
        out.append(
            f"{n} changes by {np.degrees(v):.3g} deg, more than {np.degrees(limits.angle_rad):.3g} deg "
            f"(max_angle_change_deg)"
        )
    if se is not None:
        out += _undetermined(np.asarray(se, dtype=np.float64), layout, limits, free)
    cams = [(abs(x[i]), names[i]) for i in layout.cameras if free is None or i in free]
    if cams and max(cams)[0] > limits.camera:
        v, n = max(cams)
        out.append(
            f"{n} is {x[names.index(n)]:.3g}, beyond +-{limits.camera:.3g} (max_camera_change): a camera whose "
            f"reported positions are off by {100 * v:.0f} %; such a value usually means the camera model is not "
            f"identifiable from these poses (for example all at one distance from the target): try a smaller "
            f"camera model"
        )
    return out


def _undetermined(se, layout: Layout, limits: Thresholds, free) -> list[str]:
    """The estimated parameters whose standard error is beyond the limit of their unit (frames
    included: a frame the data do not fix is as arbitrary as a DH error)."""
    names, units = layout.names(), layout.units()
    limit = {"mm": limits.length_mm, "rad": limits.angle_rad, "1": limits.camera}
    bad = [
        (se[i] / limit[units[i]], i)
        for i in range(layout.size)
        if (free is None or i in free) and units[i] in limit and not se[i] <= limit[units[i]]
    ]
    if not bad:
        return []

    def shown(i):
        value = (
            f"{np.degrees(se[i]):.3g} deg"
            if units[i] == "rad"
            else f"{se[i]:.3g}" + (" mm" if units[i] == "mm" else "")
        )
        return f"{names[i]} ({value})"

    listed = ", ".join(shown(i) for _, i in sorted(bad, reverse=True)[:4])
    return [
        f"the data do not determine {listed}: standard errors beyond the plausibility limits (a parameter "
        f"not separable from others on these poses, so its value is arbitrary; more varied poses or a "
        f"smaller model fix it)"
    ]


def variants(robot: Robot, q, target, n_points: int):
    """``{name: (q, target)}``: the data read again without each mistake of :data:`MISTAKES`."""
    out = {}
    pos = (lambda t: t[..., :3, 3]) if n_points == 0 else (lambda t: t)

    def with_pos(f):
        t = np.array(target, copy=True)
        if n_points == 0:
            t[..., :3, 3] = f(t[..., :3, 3])
        else:
            t = f(t)
        return t

    for a, b in ((0, 1), (0, 2), (1, 2)):
        perm = [0, 1, 2]
        perm[a], perm[b] = b, a
        out[f"swapped {'xyz'[a]}, {'xyz'[b]}"] = (q, with_pos(lambda p, perm=perm: p[..., perm]))
    for a in range(3):
        sign = np.ones(3)
        sign[a] = -1.0
        out[f"mirrored {'xyz'[a]}"] = (q, with_pos(lambda p, sign=sign: p * sign))
    if n_points == 0:
        for name, R in rotations_without(target[:, :3, :3]).items():
            t = np.array(target, copy=True)
            t[:, :3, :3] = R
            out[name] = (q, t)
    n = q.shape[1]
    for j in range(n - 1):
        perm = list(range(n))
        perm[j], perm[j + 1] = j + 1, j
        pair = f"{robot.joint_names[j]!r}, {robot.joint_names[j + 1]!r}"  # the columns as the file names them
        out[f"joints {j + 1} and {j + 2} swapped ({pair})"] = (q[:, perm], target)
    out["joints reversed"] = (q[:, ::-1], target)
    rev = np.array([t == "R" for t in robot.joint_types])
    out["degrees read as radians"] = (np.where(rev, np.radians(q), q), target)
    out["radians read as degrees"] = (np.where(rev, np.degrees(q), q), target)
    out["metres read as millimetres"] = (q, with_pos(lambda p: p * 1000.0))
    out["millimetres read as metres"] = (q, with_pos(lambda p: p / 1000.0))
    if not rev.all():  # a length option applies to the prismatic columns too, not always rightly
        out["prismatic joints in metres read as millimetres"] = (np.where(rev, q, q * 1000.0), target)
        out["prismatic joints in millimetres read as metres"] = (np.where(rev, q, q / 1000.0), target)
    del pos
    return out


CONVENTION_MISTAKES = {"sdh": "modified DH read as standard DH", "mdh": "standard DH read as modified DH"}
"""A DH table in the other convention than its file says, by the convention the file gives: tried
on the data as given (:func:`diagnose`)."""


FRAME_MISTAKES = {
    "base": "the measurement frame held at the robot file's base (estimate_base off: --no-estimate-base)",
    "tool": "the tool held at the robot file's (estimate_tool off: --no-estimate-tool)",
}
"""A frame the options hold known that the data put elsewhere (a tracker set up anew, another
tool): tried by :func:`diagnose` with that frame estimated."""


def diagnose(robot: Robot, q, target, n_points: int, layout: Layout, limits: Thresholds, *, memory_mb: float = 1024.0):
    """Test the likely input mistakes (module docstring), and for a DH table the other convention.

    **Returns** ``(before, ranked)``: ``before`` the frames-only ``(position RMS mm, rotation RMS
    deg or None)`` of the data as given; ``ranked`` ``[(mistake, position RMS, rotation RMS),
    ...]`` with each correction, best first (by :func:`badness`).
    """
    tried = {"as given": (q, target), **variants(robot, q, target, n_points)}
    names = list(tried)
    Q = np.stack([v[0] for v in tried.values()])
    T = np.stack([v[1] for v in tried.values()])
    res = _frames_only(robot, Q, T, n_points, layout, memory_mb)
    if robot.convention in CONVENTION_MISTAKES:  # the same table read in the other convention
        other = robot.replace(convention="mdh" if robot.convention == "sdh" else "sdh")
        names.append(CONVENTION_MISTAKES[robot.convention])
        res += _frames_only(other, Q[:1], T[:1], n_points, layout, memory_mb)
    for frame, name in FRAME_MISTAKES.items():  # a frame held at the robot file's where the data are not
        if not getattr(layout, frame):
            both = {"base": layout.base, "tool": layout.tool} | {frame: True}
            names.append(name)
            res += _frames_only(robot, Q[:1], T[:1], n_points, Layout.of(robot, **both, n_points=n_points), memory_mb)
    ranked = sorted(((m, *r) for m, r in zip(names[1:], res[1:])), key=lambda t: badness(t[1], t[2], limits))
    return res[0], ranked


def _frames_only(
    robot: Robot,
    Q: Float[np.ndarray, "R K n"],
    T: Float[np.ndarray, "R K ..."],
    n_points: int,
    layout: Layout,
    memory_mb: float,
) -> list:
    """``[(position RMS mm, rotation RMS deg or None)]`` of the frames-only fit (nominal
    kinematics, base and tool estimated) of each data set ``Q (R, K, n)``, ``T`` in one batch."""
    R, K = Q.shape[:2]
    lay = dataclasses.replace(layout, camera="none")
    kin = robot.stripped()
    masks = np.ones((R, K))
    ref = (
        core.start_models(kin, lay, Q, T, masks, shared=False)
        if lay.frames
        else core.broadcast_model(Model(kin, np.zeros((n_points, 3)) if n_points else None), R)
    )
    J0 = core.analyse(core.member(ref, 0), lay, Q[0])[0]
    ident = core.base_set(J0, lay, robot)
    base = set(ident.base)
    prior = np.array([0.0 if (i in base and i in lay.frames) else core.PIN for i in range(lay.size)])
    cfg = core.Config(lay, "lm", 50, 1e-8, 1e-8, "l2", shared_data=False)
    unit = core.weights_of(lay, np.array([core.UNIT_WEIGHTS]))
    out = core.run_members(
        cfg,
        ref,
        Q,
        T,
        masks,
        np.repeat(unit, R, 0),
        np.repeat(prior[None], R, 0),
        J0=J0,
        memory_mb=memory_mb,
        label="checking likely mistakes",
    )
    pos = np.sqrt(np.nanmean(out["pos_err"] ** 2, axis=(1, 2)))  # a lost point (NaN) left out
    rot = np.degrees(np.sqrt(np.mean(out["rot_err"] ** 2, axis=1))) if n_points == 0 else np.full(R, np.nan)
    pos, rot = np.where(np.isfinite(pos), pos, np.inf), np.where(np.isfinite(rot), rot, np.inf)
    return [(float(p), None if n_points else float(r)) for p, r in zip(pos, rot)]


def badness(pos_mm: float, rot_deg: float | None, limits: Thresholds) -> float:
    """The residual in units of its plausibility limit (the larger of position and rotation)."""
    return max(pos_mm / limits.residual_mm, 0.0 if rot_deg is None else rot_deg / limits.rotation_deg)


def _fmt(pos, rot) -> str:
    return f"{pos:.4g} mm" + ("" if rot is None else f", {rot:.3g} deg")


MIRROR_IMAGES = ("swapped x", "swapped y", "mirrored")
"""The mistakes that reflect the positions: any two differ by a rotation, which the estimated
measurement frame absorbs, so position data fit them alike (poses' rotations tell them apart)."""
TIE = 1e-3
"""Residuals within this share of each other are a tie."""


LIKELY = ". Likely cause: "
"""Where :func:`explain` names the input mistake it found (:func:`names_a_cause`)."""


def names_a_cause(why: str | None) -> bool:
    """Whether :func:`explain`'s message names a likely input mistake (not only what is wrong)."""
    return bool(why) and LIKELY in why


def explain(found: list[str], before, ranked, limits: Thresholds, *, cause: str = "") -> str:
    """One message: what is implausible, the likely cause it found (or the ones it ruled out).
    A correction counts when the residual as given is beyond the limits and the correction brings
    it within them and to less than a fifth (data that fit as given hold no input mistake, however
    much a correction shaves off a residual already at the noise). ``cause``: one already found in
    the data."""
    head = "not a calibration: " + "; ".join(found)
    if cause:
        return f"{head}{LIKELY}{cause}"
    b0 = badness(*before, limits)
    fixes = [(m, p, r) for m, p, r in ranked if badness(p, r, limits) < min(1.0, 0.2 * b0)] if b0 >= 1.0 else []
    if fixes:
        m, p, r = fixes[0]
        mirrors = sorted(
            (f[0] for f in fixes if f[0].startswith(MIRROR_IMAGES) and abs(f[1] - p) <= TIE * p), key=MISTAKES.index
        )
        if m.startswith(MIRROR_IMAGES) and len(mirrors) > 1:  # reflections differ by a turn the base takes
            return (
                f"{head}{LIKELY}a position axis swapped or mirrored ({'; '.join(mirrors)}: from positions "
                f"alone these mirror images fit alike, so which one cannot be told; with one corrected the "
                f"frames-only RMS residual drops from {_fmt(*before)} to {_fmt(p, r)}). Check the data file's "
                f"position columns; if they are right, a sign in the robot model (an alpha, a joint axis) makes "
                f"it the mirror image of the arm measured"
            )
        if m in FRAME_MISTAKES.values():
            return (
                f"{head}{LIKELY}{m}: with it estimated the frames-only RMS residual drops from {_fmt(*before)} to "
                f"{_fmt(p, r)}. The data are not measured in that frame (a tracker set up anew, another tool): "
                f"estimate it, or give the frame the data were measured in"
            )
        if m in CONVENTION_MISTAKES.values():
            return (
                f"{head}{LIKELY}the robot file's DH table is {m.replace(' read', ', read')} (in "
                f"{m.split(' read as ')[0]} the frames-only RMS residual drops from {_fmt(*before)} to {_fmt(p, r)}). "
                f'Check the robot file\'s convention (convention = "{"mdh" if m.startswith("modified") else "sdh"}")'
            )
        return (
            f"{head}{LIKELY}{m} (with that corrected, the frames-only RMS residual drops from "
            f"{_fmt(*before)} to {_fmt(p, r)}). Check the data file's columns and units"
        )
    if b0 < 1.0:
        return f"{head} (the frames-only RMS residual of the data as given is {_fmt(*before)}: no input mistake)"
    tried = ", ".join(m for m, *_ in ranked)
    return (
        f"{head}. None of the likely input mistakes explains it (tried: {tried}; the frames-only RMS residual "
        f"is {_fmt(*before)}); check the robot model against the data, or raise the thresholds if the robot "
        f"really is this far from its model"
    )
