import sys

import jax.numpy as jnp
import numpy as np

import jaxcal

sys.path.insert(0, "/work/main/tests")
from jaxcal.model import Layout, Model, jacobian

rng = np.random.default_rng(5)
nominal = jaxcal.load_robot("/work/main/jaxcal/data/tiago_mocap/tiago_arm.urdf")
n = nominal.n_joints
c = np.where(np.array(nominal.joint_types) == "R", 1e-5, 0.0)
true = nominal.replace(base=np.eye(4), compliance=c)
pts = rng.normal(0, 60, (3, 3))
lim = np.asarray(nominal.q_limits) * 0.8
q = rng.uniform(lim[:, 0], lim[:, 1], (60, n))
T = np.asarray(jaxcal.fk(true, q))
clean = np.einsum("kij,mj->kmi", T[:, :3, :3], pts) + T[:, None, :3, 3]
R, sig = 200, 0.05
meas = clean[None] + rng.normal(0, sig, (R,) + clean.shape)
res = jaxcal.calibrate_batch(nominal, np.repeat(q[None], R, 0), meas, compliance="yes", sigma_pos_mm=sig, devices=None)
names = res.names
ci = [i for i, nm in enumerate(names) if nm.startswith("compliance")]
est = res.x[:, ci]
lay = Layout.of(nominal, base=True, tool=True, n_points=3, compliance=True)
J = np.asarray(jacobian(Model(true, pts), lay, jnp.asarray(q))).reshape(-1, lay.size)
base = list(res.identifiability.base)
cov = np.linalg.inv(J[:, base].T @ J[:, base] / sig**2)
sd = np.sqrt(np.diag(cov))
idx = {b: k for k, b in enumerate(base)}
print("converged", res.converged.mean())
for i in ci:
    if i in idx:
        print(
            names[i],
            "bias/sd",
            (est[:, ci.index(i)].mean() - c[int(names[i][10:]) - 1]) / sd[idx[i]],
            "MC sd / CRLB sd",
            est[:, ci.index(i)].std() / sd[idx[i]],
        )
