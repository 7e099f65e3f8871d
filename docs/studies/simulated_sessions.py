"""Later sessions of a simulated TIAGo: how well each model, fitted on one session, predicts point 1
on three later ones, with nothing fitted again.

The truth is the bundled URDF with every joint origin moved by 1-3 mm and turned by 1-5 mrad and
joint offsets of up to 2 mrad; its forward kinematics are yourdfpy's, not jaxcal's. Four points
on the hand (the bundled data's layout), a motion-capture frame 1.8 m away, 0.25 mm noise per
coordinate. The training session is the bundled file's 37 postures; each later session repeats
them and adds 14 new postures within the training ranges and 11 beyond them (one or two joints
5-25 % of their span past the training end, within the URDF's limits). Scenario ``geometric``
has nothing else; ``non-geometric`` adds a joint compliance under the arm's own weight (masses
along the links, 0.5-3 mrad), a backlash of 0.5-1 mrad with the sign of the gravity moment, and
between sessions a motion-capture frame moved by 0.3-1 mm and 0.2-0.4 mrad.

Models: ``jaxcal calibrate``'s default (``calibrate_data``), the same with the outliers' second
look in the plain threshold (a left-out pose's prediction spread taken as 1), the same with the
pruning jaxcal used before (``scoring_rule.prune_along_all``), ``--params all`` and
``--params offsets``. For each: the RMS of point 1's error (mm) over the later sessions,
beyond the training ranges, and the poses each left out (file row, and in brackets its
error in standard deviations of the noise).

    python docs/studies/simulated_sessions.py > docs/studies/simulated_sessions.txt
"""

import io
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import yourdfpy
from scipy.spatial.transform import Rotation

import jaxcal
from jaxcal.calibration import _selection as selection
from jaxcal.calibration import _workflow
from jaxcal.model import predict

DATA = "jaxcal/data/tiago_mocap/"
SEEDS = range(5)
JOINTS = ["torso_lift_joint"] + [f"arm_{i}_joint" for i in range(1, 8)]
MARKERS = np.array([[64.5, 2.2, 68.7], [77.8, -3.6, -88.9], [170.4, -1.6, -58.6], [168.4, 5.4, 48.5]])  # mm
MASSES = np.array([2.5, 2.0, 2.0, 1.5, 1.0, 0.8, 0.5])  # kg, arm links 1-7; and 1.2 kg at the hand
FRAME = np.eye(4)
FRAME[:3, :3], FRAME[:3, 3] = Rotation.from_euler("xyz", [0.02, -0.03, 0.6]).as_matrix(), [1500.0, -900.0, 250.0]


class Arm:
    """The true arm: a perturbed copy of the URDF, by yourdfpy."""

    def __init__(self, rng):
        root = ET.parse(DATA + "tiago_arm.urdf").getroot()
        for j in root.iter("joint"):
            if j.get("type") == "fixed":
                continue
            o = j.find("origin")
            xyz = np.array(o.get("xyz").split(), float) + rng.choice([-1, 1], 3) * rng.uniform(1e-3, 3e-3, 3)
            turn = Rotation.from_rotvec(rng.choice([-1, 1], 3) * rng.uniform(1e-3, 5e-3, 3))
            rpy = (Rotation.from_euler("xyz", np.array(o.get("rpy").split(), float)) * turn).as_euler("xyz")
            o.set("xyz", " ".join(f"{v:.17g}" for v in xyz))
            o.set("rpy", " ".join(f"{v:.17g}" for v in rpy))
        self.urdf = yourdfpy.URDF.load(io.StringIO(ET.tostring(root, encoding="unicode")), load_meshes=False)
        self.limits = np.array(
            [[self.urdf.joint_map[n].limit.lower, self.urdf.joint_map[n].limit.upper] for n in JOINTS]
        )
        self.offsets = np.r_[0.0, rng.uniform(-2e-3, 2e-3, 7)]

    def frames(self, q):
        """Hand poses (mm) and, per revolute joint, its origin (mm) and axis in the base frame."""
        hands, origins, axes = [], [], []
        for qk in q:
            self.urdf.update_cfg(dict(zip(JOINTS, qk)))
            T = [np.array(self.urdf.get_transform(self.urdf.joint_map[n].child, "base_footprint")) for n in JOINTS[1:]]
            hand = np.array(self.urdf.get_transform("wrist_ft_tool_link", "base_footprint"))
            hand[:3, 3] *= 1e3
            hands.append(hand)
            origins.append([t[:3, 3] * 1e3 for t in T])
            axes.append([t[:3, :3] @ self.urdf.joint_map[n].axis for t, n in zip(T, JOINTS[1:])])
        return np.array(hands), np.array(origins), np.array(axes)

    def moments(self, q):
        """Gravity moment (N mm) about each revolute axis of the links' and the hand's weight."""
        hand, o, a = self.frames(q)
        ends = np.concatenate([o[:, 1:], hand[:, None, :3, 3]], 1)
        masses = [(MASSES[i], 0.5 * (o[:, i] + ends[:, i])) for i in range(7)]
        masses.append((1.2, hand[:, :3, 3] + 100.0 * hand[:, :3, 0]))
        g = np.array([0.0, 0.0, -9.81])
        tau = np.zeros((len(q), 8))
        for i in range(7):
            for m, p in masses[i:]:
                tau[:, i + 1] += np.einsum("kc,kc->k", np.cross(p - o[:, i], m * g), a[:, i])
        return tau


def points(arm, q, effects, frame, rng):
    qa = q + arm.offsets
    if effects is not None:
        tau = arm.moments(qa)
        qa = qa + effects["compliance"] * tau + effects["backlash"] * np.sign(tau)
    hand = frame @ arm.frames(qa)[0]
    return (
        np.einsum("kij,mj->kmi", hand[:, :3, :3], MARKERS) + hand[:, None, :3, 3] + rng.normal(0, 0.25, (len(q), 4, 3))
    )


def later_postures(q, limits, rng):
    """14 new postures within the training ranges, 11 with one or two joints beyond them."""
    lo, hi = q.min(0), q.max(0)

    def between():
        a, b = q[rng.integers(len(q), size=2)]
        return np.clip(a + rng.uniform() * (b - a) + rng.normal(0, 0.05, 8) * (hi - lo), lo, hi)

    inside, beyond = [between() for _ in range(14)], []
    while len(beyond) < 11:
        p = between()
        for j in rng.permutation(8)[: rng.integers(1, 3)]:
            v = (
                (hi[j] + rng.uniform(0.05, 0.25) * (hi[j] - lo[j]))
                if rng.uniform() < 0.5
                else (lo[j] - rng.uniform(0.05, 0.25) * (hi[j] - lo[j]))
            )
            if limits[j, 0] < v < limits[j, 1]:
                p[j] = v
        if np.any((p < lo - 1e-9) | (p > hi + 1e-9)):
            beyond.append(p)
    return np.array(inside), np.array(beyond)


def fits(robot, meas):
    """The models compared: name -> (calibrated model, poses left out)."""
    from scoring_rule import prune_along_all  # the study beside this one (this file run as a script)

    out = {}
    for name, kw in (
        ("default", {}),
        ("default, plain second look", {}),
        ("default, pruned along all poses' order", {}),
        ("all", {"params": "all"}),
        ("offsets", {"params": "offsets"}),
    ):
        spread, prune = _workflow._prediction_spread, selection.prune
        if name.endswith("plain second look"):
            _workflow._prediction_spread = lambda *a: 1.0
        if name.endswith("pruned along all poses' order"):
            selection.prune = prune_along_all
        try:
            res = jaxcal.calibrate_data(robot, meas, **kw)
        finally:
            _workflow._prediction_spread, selection.prune = spread, prune
        out[name] = (res.model, [f"{o['row']} ({o['sigmas']:.0f})" for o in res.report["outliers"]])
    return out


def main():
    warnings.simplefilter("ignore")
    robot = jaxcal.load_robot(DATA + "tiago_arm.urdf")
    rows = np.genfromtxt(DATA + "training.csv", delimiter=",", names=True)
    q = np.stack([rows[n] for n in JOINTS], 1)
    to_mm = np.r_[1e3, np.ones(7)]  # the torso slides: mm inside
    print(__doc__.split("\n\n")[0].replace("\n", " "))
    print(f"{'scenario':>16s} {'seed':>4s} {'model':>28s} {'later RMS (mm)':>15s} {'beyond (mm)':>12s}  left out")
    table = {}
    for scenario in ("geometric", "non-geometric"):
        for seed in SEEDS:
            rng = np.random.default_rng([seed, 0])
            arm = Arm(rng)
            effects = None
            if scenario == "non-geometric":
                peak = np.abs(arm.moments(q + arm.offsets)).max(0)
                live = peak > 500.0  # joints the weight loads (not the vertical arm_1, not the torso)
                effects = {
                    "compliance": np.where(live, rng.uniform(0.5e-3, 3e-3, 8) / np.maximum(peak, 1e-9), 0.0),
                    "backlash": np.where(live, rng.uniform(0.5e-3, 1e-3, 8), 0.0),
                }
            meas = jaxcal.Measurements(q * to_mm, points(arm, q, effects, FRAME, rng))
            later = []
            for _ in range(3):
                inside, beyond = later_postures(q, arm.limits, rng)
                ql = np.concatenate([q, inside, beyond])
                frame = FRAME.copy()
                if effects is not None:  # the motion-capture frame moved between sessions
                    v, w = rng.normal(size=3), rng.normal(size=3)
                    shift = v / np.linalg.norm(v) * rng.uniform(0.3, 1.0)
                    turn = w / np.linalg.norm(w) * rng.uniform(0.2e-3, 0.4e-3)
                    frame[:3, :3] = Rotation.from_rotvec(turn).as_matrix() @ frame[:3, :3]
                    frame[:3, 3] = Rotation.from_rotvec(turn).as_matrix() @ frame[:3, 3] + shift
                p1 = points(arm, ql, effects, frame, rng)[:, 0]
                later.append((ql, p1, np.arange(len(ql)) >= len(q) + len(inside)))
            ql = np.concatenate([x[0] for x in later])
            p1 = np.concatenate([x[1] for x in later])
            out = np.concatenate([x[2] for x in later])
            for name, (model, left) in fits(robot, meas).items():
                e = np.linalg.norm(np.asarray(predict(model, ql * to_mm))[:, 0] - p1, axis=-1)
                rms, far = float(np.sqrt(np.mean(e**2))), float(np.sqrt(np.mean(e[out] ** 2)))
                table.setdefault((scenario, name), []).append((rms, far))
                left = ", ".join(left) or "-"
                print(f"{scenario:>16s} {seed:>4d} {name:>28s} {rms:>15.3f} {far:>12.3f}  {left}", flush=True)
    print(f"\nmean over seeds {list(SEEDS)}")
    print(f"{'scenario':>16s} {'model':>28s} {'later RMS (mm)':>15s} {'beyond (mm)':>12s}")
    for (scenario, name), v in table.items():
        m = np.mean(v, 0)
        print(f"{scenario:>16s} {name:>28s} {m[0]:>15.3f} {m[1]:>12.3f}")


if __name__ == "__main__":
    main()
