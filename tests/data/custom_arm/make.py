"""Generate a perturbed 'true' URDF and measurement CSVs (train + fresh) with yourdfpy FK."""

import argparse
import sys
import xml.etree.ElementTree as ET

import numpy as np
import yourdfpy

ap = argparse.ArgumentParser()
ap.add_argument("--urdf", required=True)
ap.add_argument("--base")
ap.add_argument("--tip")
ap.add_argument("--out", required=True)
ap.add_argument("--n", type=int, default=60)
ap.add_argument("--nfresh", type=int, default=40)
ap.add_argument("--npts", type=int, default=1)
ap.add_argument("--noise-mm", type=float, default=0.03)
ap.add_argument("--seed", type=int, default=0)
ap.add_argument("--pos-mm", type=float, default=1.0)
ap.add_argument("--rot-mrad", type=float, default=3.0)
ap.add_argument("--deg", action="store_true")
ap.add_argument("--shuffle", action="store_true")
ap.add_argument("--extra", action="store_true")
ap.add_argument("--perturb-fixed", action="store_true")
ap.add_argument("--quat", action="store_true")
ap.add_argument("--compl", type=float, default=0.0)
ap.add_argument("--rot-noise-mrad", type=float, default=0.0)
ap.add_argument("--identity-meas", action="store_true")
a = ap.parse_args()
rng = np.random.default_rng(a.seed)

tree = ET.parse(a.urdf)
root = tree.getroot()
joints = root.findall("joint")
child_of = {j.find("child").get("link"): j for j in joints}
links = [l.get("name") for l in root.findall("link")]
parents = {j.find("parent").get("link") for j in joints}
base = a.base or [l for l in links if l not in child_of][0]
tip = a.tip
if tip is None:
    # the one leaf below base... just require it
    sys.exit("give --tip")
chain = []
l = tip
while l != base:
    j = child_of[l]
    chain.append(j)
    l = j.find("parent").get("link")
chain.reverse()


def mimic(j):
    return j.find("mimic") is not None


movable = [j for j in chain if j.get("type") in ("revolute", "continuous", "prismatic") and not mimic(j)]
print("chain:", [(j.get("name"), j.get("type")) for j in chain])
for j in chain:
    if j.get("type") == "fixed" and not a.perturb_fixed:
        continue
    o = j.find("origin")
    if o is None:
        o = ET.SubElement(j, "origin")
    xyz = np.array([float(v) for v in (o.get("xyz") or "0 0 0").split()])
    rpy = np.array([float(v) for v in (o.get("rpy") or "0 0 0").split()])
    xyz += rng.normal(0, a.pos_mm * 1e-3, 3)
    rpy += rng.normal(0, a.rot_mrad * 1e-3, 3)
    o.set("xyz", " ".join(repr(float(v)) for v in xyz))
    o.set("rpy", " ".join(repr(float(v)) for v in rpy))
true_path = a.out + "_true.urdf"
tree.write(true_path)
robot = yourdfpy.URDF.load(true_path, load_meshes=False, build_collision_scene_graph=False, load_collision_meshes=False)
names = [j.get("name") for j in movable]
lims = []
for j in movable:
    lim = j.find("limit")
    if j.get("type") == "continuous" or lim is None or lim.get("lower") is None:
        lo, hi = -np.pi, np.pi
    else:
        lo, hi = float(lim.get("lower")), float(lim.get("upper"))
    c, h = (lo + hi) / 2, (hi - lo) / 2 * 0.85
    lims.append((c - h, c + h))
lims = np.array(lims)


def rotm(rv):
    th = np.linalg.norm(rv)
    k = rv / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


T_mb = np.eye(4)
if not a.identity_meas:
    T_mb[:3, :3] = rotm(np.array([0.3, -0.5, 1.2]))
    T_mb[:3, 3] = [1.2, -0.4, 0.3]
pts = rng.uniform(-0.08, 0.08, (a.npts, 3)) + np.array([0, 0, 0.05])


def fk(q):
    cfg = dict(zip(names, q))
    robot.update_cfg(cfg)
    if a.compl:
        p = robot.get_transform(tip, base)[:3, 3]
        dq = []
        for j in movable:
            Tj = robot.get_transform(j.find("child").get("link"), base)
            u = Tj[:3, :3] @ np.array([float(v) for v in j.find("axis").get("xyz").split()])
            u /= np.linalg.norm(u)
            tau = u @ np.cross((p - Tj[:3, 3]) * 1e3, np.array([0, 0, -1.0]))
            dq.append(a.compl * tau if j.get("type") != "prismatic" else 0.0)
        robot.update_cfg(dict(zip(names, np.asarray(q) + np.array(dq))))
    return robot.get_transform(tip, base)


def make(n, fn):
    Q = rng.uniform(lims[:, 0], lims[:, 1], (n, len(names)))
    P = []
    quats = []
    for q in Q:
        T = T_mb @ fk(q)
        p = (T[:3, :3] @ pts.T).T + T[:3, 3]
        P.append(p)
        from scipy.spatial.transform import Rotation as R

        Rn = R.from_rotvec(rng.normal(0, a.rot_noise_mrad * 1e-3, 3)) if a.rot_noise_mrad > 0 else R.identity()
        quats.append((Rn * R.from_matrix(T[:3, :3])).as_quat()[[3, 0, 1, 2]])
    P = np.array(P)
    Pn = P + rng.normal(0, a.noise_mm * 1e-3, P.shape)
    cols = []
    data = []
    list(names)
    Qw = np.degrees(Q) if a.deg else Q
    if a.deg:  # prismatic stays in m
        for i, j in enumerate(movable):
            if j.get("type") == "prismatic":
                Qw[:, i] = Q[:, i]
    for i, nm in enumerate(names):
        cols.append(nm)
        data.append(Qw[:, i])
    if a.npts == 1:
        for k, c in enumerate("xyz"):
            cols.append(c)
            data.append(Pn[:, 0, k])
        if a.quat:
            Qa = np.array(quats)
            for k, c in enumerate(["qw", "qx", "qy", "qz"]):
                cols.append(c)
                data.append(Qa[:, k])
    else:
        for m in range(a.npts):
            for k, c in enumerate("xyz"):
                cols.append(f"{c}{m + 1}")
                data.append(Pn[:, m, k])
    if a.extra:
        cols.append("timestamp")
        data.append(np.arange(n) * 1.5)
        cols.append("note_val")
        data.append(rng.normal(size=n))
    order = list(range(len(cols)))
    if a.shuffle:
        order = list(rng.permutation(len(cols)))
    with open(fn, "w") as f:
        f.write(",".join(cols[i] for i in order) + "\n")
        for r in range(n):
            f.write(",".join(repr(float(data[i][r])) for i in order) + "\n")
    return Q, P


Qt, Pt = make(a.n, a.out + "_train.csv")
Qf, Pf = make(a.nfresh, a.out + "_fresh.csv")
np.savez(
    a.out + "_truth.npz", Qf=Qf, Pf=Pf, Qt=Qt, Pt=Pt, T_mb=T_mb, pts=pts, names=np.array(names), base=base, tip=tip
)
print("wrote", a.out, "joints", names, "pts", pts)
