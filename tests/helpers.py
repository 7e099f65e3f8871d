"""Test helpers: random robots and transforms, and the command line run in-process."""

import functools

import numpy as np
import pytest


def random_dh(rng, n=6, *, lengths=300.0):
    """A random, generic DH table (mm, rad)."""
    return np.c_[
        rng.uniform(-np.pi, np.pi, n),
        rng.uniform(-lengths, lengths, n),
        rng.uniform(-lengths, lengths, n),
        rng.uniform(-np.pi, np.pi, n),
    ]


def random_transform(rng, scale=100.0):
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.normal(size=3) * scale
    return T


def run_cli(monkeypatch, capsys, *args):
    """`jaxcal ARGS` in-process through the real entry point `jaxcal.cli.main`; returns
    (exit code, stdout, stderr)."""
    import sys

    from jaxcal.cli import main

    monkeypatch.setattr(sys, "argv", ["jaxcal", *map(str, args)])
    with pytest.raises(SystemExit) as e:
        main()
    out = capsys.readouterr()
    return e.value.code, out.out, out.err


def dh_fk(dh, q, *, convention="sdh", joint_types=None, base=None, tool=None):
    """End poses ``(K, 4, 4)`` by a plain NumPy product of DH link matrices: a forward
    kinematics written apart from jaxcal's, to generate test data."""
    dh, q = np.asarray(dh, float), np.atleast_2d(np.asarray(q, float))
    joint_types = joint_types or "R" * len(dh)

    def rz(t):
        c, s = np.cos(t), np.sin(t)
        return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])

    def rx(t):
        c, s = np.cos(t), np.sin(t)
        return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]])

    def tr(x, z):
        T = np.eye(4)
        T[0, 3], T[2, 3] = x, z
        return T

    out = []
    for qk in q:
        T = np.eye(4) if base is None else np.array(base, float)
        for (theta, d, a, alpha), qi, kind in zip(dh, qk, joint_types):
            theta, d = (theta + qi, d) if kind == "R" else (theta, d + qi)
            if convention == "sdh":
                T = T @ rz(theta) @ tr(0, d) @ tr(a, 0) @ rx(alpha)
            else:
                T = T @ rx(alpha) @ tr(a, 0) @ rz(theta) @ tr(0, d)
        out.append(T if tool is None else T @ np.asarray(tool, float))
    return np.array(out)


def measurement_csv(q, poses, *, position_only=False, rng=None, sigma_mm=0.0, sigma_rad=0.0, joint_names=None):
    """CSV text of joint values and measured poses (mm, rad; quaternion w, x, y, z), written
    without jaxcal, with seeded Gaussian noise."""
    from scipy.spatial.transform import Rotation

    q, poses = np.asarray(q, float), np.asarray(poses, float)
    n = q.shape[1]
    names = list(joint_names or [f"q{i + 1}" for i in range(n)])
    p = poses[:, :3, 3].copy()
    R = Rotation.from_matrix(poses[:, :3, :3])
    if rng is not None:
        p = p + rng.normal(scale=sigma_mm, size=p.shape)
        R = Rotation.from_rotvec(rng.normal(scale=sigma_rad, size=(len(q), 3))) * R
    header = names + ["x", "y", "z"] + ([] if position_only else ["qw", "qx", "qy", "qz"])
    quat = R.as_quat()[:, [3, 0, 1, 2]]
    lines = [",".join(header)]
    for k in range(len(q)):
        vals = list(q[k]) + list(p[k]) + ([] if position_only else list(quat[k]))
        lines.append(",".join(repr(float(v)) for v in vals))
    return "\n".join(lines) + "\n"


UR_DH = {
    "ur5": (0.089159, -0.425, -0.39225, 0.10915, 0.09465, 0.0823),
    "ur10e": (0.1807, -0.6127, -0.57155, 0.17415, 0.11985, 0.11655),
}
"""UR's published nominal DH (m, rad): d1, a2, a3, d4, d5, d6; alpha = pi/2, 0, 0, pi/2, -pi/2, 0."""


def ur_nominal_origins(name):
    """UR's nominal kinematics file, entry by entry (x, y, z, roll, pitch, yaw; m, rad): shoulder
    z = d1, upper_arm roll = alpha1, forearm x = a2, wrist_1 x = a3 and z = d4, wrist_2 y = -d5
    and roll = pi/2, wrist_3 y = d6 and a turn by alpha5 = -pi/2 about x."""
    d1, a2, a3, d4, d5, d6 = UR_DH[name]
    return {
        "shoulder": (0, 0, d1, 0, 0, 0),
        "upper_arm": (0, 0, 0, np.pi / 2, 0, 0),
        "forearm": (a2, 0, 0, 0, 0, 0),
        "wrist_1": (a3, 0, d4, 0, 0, 0),
        "wrist_2": (0, -d5, 0, np.pi / 2, 0, 0),
        "wrist_3": (0, d6, 0, -np.pi / 2, 0, 0),
    }


def ur5_factory_doc(rng, pos_m=3e-4, rot_rad=3e-3):
    """A UR kinematics document (PyYAML's dict) of a UR5 as its factory calibration writes one:
    UR's nominal origins, each moved off the DH form by seeded Gaussian errors (metres,
    radians). Written without jaxcal."""
    kin = {}
    for key, v in ur_nominal_origins("ur5").items():
        v = np.asarray(v, float) + np.r_[rng.normal(0, pos_m, 3), rng.normal(0, rot_rad, 3)]
        kin[key] = dict(zip(("x", "y", "z", "roll", "pitch", "yaw"), map(float, v)))
    return {"kinematics": {**kin, "hash": "calib_12345"}}


def ur_yaml_fk(doc, q):
    """Frames of ``wrist_3_link`` in ``base_link_inertia`` (``(K, 4, 4)``, metres) from a UR
    kinematics document (PyYAML's dict): each joint's origin ``xyz`` and URDF roll-pitch-yaw
    (``Rz(yaw) Ry(pitch) Rx(roll)``), then a turn by ``q_i`` about its z. NumPy only, apart
    from jaxcal."""

    def rot(axis, t):
        c, s = np.cos(t), np.sin(t)
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        R = np.eye(4)
        R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
        return R

    kin = doc["kinematics"]
    out = []
    for qk in np.atleast_2d(np.asarray(q, float)):
        T = np.eye(4)
        for key, qi in zip(("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3"), qk):
            e = kin[key]
            O = rot(2, e["yaw"]) @ rot(1, e["pitch"]) @ rot(0, e["roll"])
            O[:3, 3] = e["x"], e["y"], e["z"]
            T = T @ O @ rot(2, qi)
        out.append(T)
    return np.array(out)


def pairwise_distances(p):
    """``(K, K)`` distances between the points ``p (K, 3)``: what two descriptions of one arm in
    different base frames agree on."""
    p = np.asarray(p)
    return np.linalg.norm(p[:, None] - p[None], axis=-1)


UR5_TRACKER = dict(n_poses=40, sigma_pos=0.05, folds=3, params="all")
"""A laser tracker's data of a UR5 (one reflector, positions only): the shapes the UR export,
report and accuracy tests share, so their calibrations share compiled programs."""


@functools.cache
def ur5_tracker(n_robots: int = 160):
    """``(nominal, sim, data, result)``: ``n_robots`` simulated UR5s (random DH errors, base and
    tool) measured by a tracker at the same poses, and the workflow's calibration of the first
    (``jaxcal.calibrate_data`` with :data:`UR5_TRACKER`'s options, noise as simulated)."""
    import jaxcal
    from jaxcal.simulation import simulate

    ur5 = jaxcal.preset("ur5")
    base = np.eye(4)
    base[:3, 3] = [800.0, -300.0, 100.0]
    rng = np.random.default_rng(37)
    q = rng.uniform(-np.pi, np.pi, (UR5_TRACKER["n_poses"], 6))
    q_val = rng.uniform(-np.pi, np.pi, (30, 6))
    s = UR5_TRACKER["sigma_pos"]
    sim = simulate(
        ur5.replace(base=base), n_robots=n_robots, q=q, q_val=q_val, seed=37, sigma_pos=s, base=True, tool=True
    )
    data = jaxcal.Measurements(q, sim.measured[0, :, None, :3, 3])
    res = jaxcal.calibrate_data(ur5, data, folds=UR5_TRACKER["folds"], params=UR5_TRACKER["params"], sigma_pos_mm=s)
    return ur5, sim, data, res


def solve_keys(monkeypatch, program: str = "_members") -> dict:
    """Record the keys of one of the calibration's kept programs (``jaxcal.calibration._core``'s
    ``_members``, the solve, or ``_nominal``, the analysis) as they are prepared in the background
    (``jaxcal._config.jit(...).prepare``) and as they are called: ``{"prepared": [...],
    "called": [...]}``. A prepared key that no call uses is a compile wasted."""
    from jaxcal.calibration import _core

    store = getattr(_core, program).kept[True]
    keys = {"prepared": [], "called": []}

    def spy(name, method):
        def wrapped(folder, args, kwargs):
            keys[name].append(store._find(args, kwargs)[0])
            return method(folder, args, kwargs)

        return wrapped

    monkeypatch.setattr(store, "prepare", spy("prepared", store.prepare))
    monkeypatch.setattr(store, "call", spy("called", store.call))
    return keys


def urdf_perturbed(text: str, rng, shift_m: float, turn_rad: float) -> str:
    """The URDF ``text`` with every joint's ``<origin>`` moved by up to ``shift_m`` per axis and
    turned by up to ``turn_rad`` per rpy angle (uniform): an arm that differs from its file."""
    import re

    def origin(m):
        tag = m.group(0)
        for attr, step in (("xyz", shift_m), ("rpy", turn_rad)):
            old = re.search(attr + r'="([^"]*)"', tag)
            v = np.array([float(x) for x in old.group(1).split()]) if old else np.zeros(3)
            new = f'{attr}="' + " ".join(repr(float(x)) for x in v + rng.uniform(-step, step, 3)) + '"'
            tag = tag.replace(old.group(0), new) if old else tag.replace("<origin", f"<origin {new}", 1)
        return tag

    def joint(m):
        j = m.group(0)
        if "<origin" not in j:
            j = j.replace("</joint>", '<origin xyz="0 0 0" rpy="0 0 0"/></joint>')
        return re.sub(r"<origin[^>]*>", origin, j)

    return re.sub(r"<joint\s.*?</joint>", joint, text, flags=re.S)


def load_urdf(path):
    """A URDF read by yourdfpy (kinematics only): a forward kinematics apart from jaxcal's."""
    import yourdfpy

    return yourdfpy.URDF.load(str(path), build_scene_graph=True, load_meshes=False, build_collision_scene_graph=False)


def urdf_chain(urdf, base: str, tip: str):
    """The movable joints from ``base`` to ``tip`` and their limits (file units), by yourdfpy."""
    by_child = {j.child: j for j in urdf.robot.joints}
    joints, link = [], tip
    while link != base:
        joints.append(by_child[link])
        link = by_child[link].parent
    moving = [j for j in joints[::-1] if j.type != "fixed"]
    lim = [(-np.pi, np.pi) if j.type == "continuous" else (j.limit.lower, j.limit.upper) for j in moving]
    return [j.name for j in moving], np.array(lim)


def urdf_points(urdf, names, q, frame_from: str, frame_to: str, point=np.zeros(3)) -> np.ndarray:
    """``point`` of ``frame_to`` in ``frame_from`` (mm) at each posture, by yourdfpy's scene graph."""
    out = []
    for row in q:
        urdf.update_cfg(dict(zip(names, row)))
        T = np.asarray(urdf.get_transform(frame_to=frame_to, frame_from=frame_from))
        out.append((T[:3, :3] @ point + T[:3, 3]) * 1e3)
    return np.array(out)


TILTED_JOINTS = (
    ("0 0 1", "0 0 0.3"), ("1 0 0", "0.2 0 0.1"), ("0.999 0.014 0.045", "0 0.25 0"), ("0 1 0", "0.1 0 0.2"),
    ("0 0 1", "0 0.1 0.15"),
)  # fmt: skip
"""(axis, origin xyz in m) of a made-up arm's revolute joints, the third's axis a little off x
(a humanoid's elbow in example-robot-data has such an axis)."""


def tilted_arm(n: int = 5) -> str:
    """The URDF text of the first ``n`` joints of :data:`TILTED_JOINTS`, links ``l0 .. ln``, every
    origin turned by rpy (0.1, -0.2, 0.3), limits +-2 rad."""
    joints = TILTED_JOINTS[:n]
    links = "".join(f'<link name="l{i}"/>' for i in range(len(joints) + 1))
    text = "".join(
        f'<joint name="j{i + 1}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
        f'<origin xyz="{xyz}" rpy="0.1 -0.2 0.3"/><axis xyz="{axis}"/>'
        f'<limit lower="-2" upper="2" effort="1" velocity="1"/></joint>'
        for i, (axis, xyz) in enumerate(joints)
    )
    return f'<robot name="r">{links}{text}</robot>'


def tilted_arm_links(folder, seed: int):
    """The five-joint :func:`tilted_arm`, every origin moved by up to 3 mm and 3 mrad (seeded), three
    points on its tip link measured by yourdfpy on the moved file (0.01 mm noise, 60 postures,
    a tracker frame 1 m off), calibrated by :func:`jaxcal.calibrate` and written as URDF into
    ``folder``. **Returns** ``(result, worst mm, worst deg)``: the largest distance and turn of a
    link's frame in the written file from the moved file's, read by yourdfpy, over five postures."""
    from pathlib import Path

    import jaxcal

    folder = Path(folder)
    nominal = folder / "arm.urdf"
    nominal.write_text(tilted_arm(5))
    rng = np.random.default_rng(seed)
    (folder / "true.urdf").write_text(urdf_perturbed(nominal.read_text(), rng, 3e-3, 3e-3))
    truth = load_urdf(folder / "true.urdf")
    names, _ = urdf_chain(truth, "l0", "l5")
    frame = random_transform(rng, 1000.0)  # the tracker's, mm
    q = rng.uniform(-2, 2, (60, len(names)))
    on_tip = ([0.05, 0, 0.02], [0, 0.04, 0.03], [-0.03, -0.02, 0.06])  # m
    moved = [urdf_points(truth, names, q, "l0", "l5", np.array(v)) for v in on_tip]
    p = np.stack([m @ frame[:3, :3].T + frame[:3, 3] for m in moved], 1)
    r = jaxcal.calibrate(jaxcal.load_robot(nominal), q, p + rng.normal(scale=0.01, size=p.shape))
    jaxcal.save_model(r.model, folder / "cal.urdf", template=nominal)
    written = load_urdf(folder / "cal.urdf")
    mm = np.diag([1e3, 1e3, 1e3, 1.0])
    far = turn = 0.0
    for qk in q[:5]:
        truth.update_cfg(dict(zip(names, qk)))
        written.update_cfg(dict(zip(names, qk)))
        for link in [f"l{i}" for i in range(1, 6)]:
            T_true = frame @ mm @ truth.get_transform(link, "l0") @ np.linalg.inv(mm)
            T_cal = mm @ written.get_transform(link, "jaxcal_measurement_frame") @ np.linalg.inv(mm)
            far = max(far, float(np.linalg.norm(T_true[:3, 3] - T_cal[:3, 3])))
            c = (np.trace(T_true[:3, :3].T @ T_cal[:3, :3]) - 1) / 2
            turn = max(turn, float(np.degrees(np.arccos(np.clip(c, -1, 1)))))
    return r, far, turn


UR5_DH = np.array(
    [
        [0.0, 89.159, 0.0, np.pi / 2],
        [0.0, 0.0, -425.0, 0.0],
        [0.0, 0.0, -392.25, 0.0],
        [0.0, 109.15, 0.0, np.pi / 2],
        [0.0, 94.65, 0.0, -np.pi / 2],
        [0.0, 82.3, 0.0, 0.0],
    ]
)
"""UR5's standard-DH table (mm, rad), as Universal Robots publish it."""


def bent_ur5(n_poses=60, sigma=0.05, *, q=None, seed=9):
    """A UR5 (NumPy FK, :data:`UR5_DH` perturbed) whose shoulder and elbow bend under a weight at
    the flange (moments by finite differences of the tool's height: the virtual work of a unit
    weight), one marker, seen from an unknown frame: ``(dh, base, c, tau, q, points)``; ``q``
    (radians) or ``n_poses`` drawn in [-2, 2]."""
    rng = np.random.default_rng(seed)
    dh = UR5_DH + np.stack([rng.normal(0, s, 6) for s in (0.001, 0.5, 0.5, 0.001)], 1)
    base = random_transform(rng, 1000.0)
    c = np.array([0.0, 1.1e-6, 0.6e-6, 0.6e-6, 0.0, 0.0])

    def tau(q, h=1e-6):  # -dz/dq_i of the flange origin, central differences
        out = np.empty_like(q)
        for i in range(6):
            dq = np.zeros(6)
            dq[i] = h
            out[:, i] = -(dh_fk(dh, q + dq)[:, 2, 3] - dh_fk(dh, q - dq)[:, 2, 3]) / (2 * h)
        return out

    q = rng.uniform(-2.0, 2.0, (n_poses, 6)) if q is None else np.asarray(q, float)
    T = base @ dh_fk(dh, q + c * tau(q))
    p = T[:, :3, :3] @ np.array([40.0, -30.0, 90.0]) + T[:, :3, 3] + rng.normal(0, sigma, (len(q), 3))
    return dh, base, c, tau, q, p
