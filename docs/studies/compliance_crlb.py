"""Monte Carlo of the joint-compliance estimate against its Cramér–Rao bound.

A TIAGo arm with a compliance of 1e-5 rad/mm on every revolute joint, three points on the hand,
60 postures, 0.05 mm noise per coordinate; 200 data sets calibrated at once
(``jaxcal.calibrate_batch``, ``compliance="yes"``). For each identifiable compliance it prints
the bias and the Monte Carlo standard deviation in units of the bound's.

    python docs/studies/compliance_crlb.py > docs/studies/compliance_crlb.txt
"""

import jax.numpy as jnp
import numpy as np

import jaxcal
from jaxcal.model import Layout, Model, jacobian

R, SIGMA, SEED = 200, 0.05, 5


def main():
    rng = np.random.default_rng(SEED)
    nominal = jaxcal.load_robot("jaxcal/data/tiago_mocap/tiago_arm.urdf")
    n = nominal.n_joints
    c = np.where(np.array(nominal.joint_types) == "R", 1e-5, 0.0)
    true = nominal.replace(base=np.eye(4), compliance=c)
    pts = rng.normal(0, 60, (3, 3))
    lim = np.asarray(nominal.q_limits) * 0.8
    q = rng.uniform(lim[:, 0], lim[:, 1], (60, n))
    T = np.asarray(jaxcal.fk(true, q))
    clean = np.einsum("kij,mj->kmi", T[:, :3, :3], pts) + T[:, None, :3, 3]
    meas = clean[None] + rng.normal(0, SIGMA, (R,) + clean.shape)
    res = jaxcal.calibrate_batch(
        nominal, np.repeat(q[None], R, 0), meas, compliance="yes", sigma_pos_mm=SIGMA, devices=None
    )
    lay = Layout.of(nominal, base=True, tool=True, n_points=3, compliance=True)
    J = np.asarray(jacobian(Model(true, pts), lay, jnp.asarray(q))).reshape(-1, lay.size)
    base = list(res.identifiability.base)
    sd = np.sqrt(np.diag(np.linalg.inv(J[:, base].T @ J[:, base] / SIGMA**2)))
    print(f"{R} data sets, {len(q)} postures, sigma {SIGMA} mm; converged {res.converged.mean():.3f}")
    print(f"{'parameter':>13s} {'bias / bound':>13s} {'MC sd / bound':>14s}")
    for i, name in enumerate(res.names):
        if name.startswith("compliance") and i in base:
            est = res.x[:, i]
            truth = c[int(name.removeprefix("compliance")) - 1]
            b = sd[base.index(i)]
            print(f"{name:>13s} {(est.mean() - truth) / b:13.3f} {est.std() / b:14.3f}")


if __name__ == "__main__":
    main()
