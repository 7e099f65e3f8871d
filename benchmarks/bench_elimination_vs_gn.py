"""Elimination (robust and literal) vs Gauss–Newton on the same measured poses.

    python benchmarks/bench_elimination_vs_gn.py [--robot paper-6r] [--robots 200] [--pairs 4]

For each robot preset: ``R`` true robots (default error scales, :func:`jaxcal.simulate.error_scales`),
one elimination design (:func:`jaxcal.design.design_poses`, ``2 (N-1) pairs + abs`` poses)
measured with noise; every method sees exactly these poses (the same measurement budget).
GN additionally runs on as many uniformly drawn poses (its natural design), for reference.

Reported: parameter error on the identifiable set (estimate vs ``C @ x_true``, the first-order
combination each base parameter estimates, :mod:`jaxcal.identifiability`), validation position
RMS on 50 held-out poses against the true robot, convergence, and wall time of the compiled,
vmapped batch (median of repeats, in this run) and compile time (first call minus the median).
"""

from __future__ import annotations

import argparse
import os
import statistics

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _util import machine, timed  # noqa: E402

import jaxcal  # noqa: E402
from jaxcal import design  # noqa: E402
from jaxcal import simulate as S  # noqa: E402
from jaxcal.calibrate import _solve_batch, identify  # noqa: E402
from jaxcal.error_model import perturb  # noqa: E402
from jaxcal.kinematics import fk  # noqa: E402
from jaxcal.solvers import elimination as el  # noqa: E402


def val_rms(robot, x, q_val, true_val):
    T = jax.jit(jax.vmap(lambda xx, qv: fk(perturb(robot, xx), qv)))(jnp.asarray(x), jnp.asarray(q_val))
    d = np.linalg.norm(np.asarray(T)[..., :3, 3] - true_val[..., :3, 3], axis=-1)
    return np.sqrt(np.mean(d ** 2, axis=-1))  # per robot


def param_err(x, x_true, ident, names):
    C = ident.combination_matrix
    e = np.asarray(x)[:, list(ident.base)] - np.asarray(x_true) @ C.T
    rad = np.array([names[j].startswith(("theta", "alpha")) for j in ident.base])
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    return {"rms_mm": float(np.sqrt(np.mean(rms[~rad] ** 2))), "rms_rad": float(np.sqrt(np.mean(rms[rad] ** 2))),
            "max_abs": float(np.abs(e).max())}


def run(name, R, pairs, n_abs, sp, sr, seed, repeats):
    robot = jaxcal.preset(name)
    qd = np.asarray(design.design_poses(jax.random.PRNGKey(seed), robot, n_pairs=pairs, n_abs=n_abs))
    K = qd.shape[0]
    plan = el.make_plan(robot, qd)
    ident = identify(robot, qd)
    names = ident.names
    print(f"\n=== {name}: {R} robots, design {pairs} pairs/step + {n_abs} abs = {K} poses, "
          f"noise {sp} mm / {sr} rad ===")
    print(plan.report())
    print("GN base set on the same poses fixes:", ", ".join(ident.fixed_names) or "none",
          "|", "; ".join(ident.combinations) or "")
    if set(plan.fixed) != set(ident.fixed):
        print("NOTE: elimination and GN hold different parameters fixed")
    scales = S.error_scales(robot)
    scales0 = scales.copy()
    scales0[list(plan.fixed)] = 0.0
    q_uni = np.asarray(S.sample_poses(jax.random.PRNGKey(seed + 1), robot, (K,)))
    ident_uni = identify(robot, q_uni)
    rows = []
    for label, sc, noise in (("noise-free, fixed params' truth = 0", scales0, (0.0, 0.0)),
                             ("noise-free, all params perturbed", scales, (0.0, 0.0)),
                             (f"noisy {sp} mm / {sr} rad", scales, (sp, sr))):
        sim = S.simulate(robot, n_robots=R, q=qd, scales=sc, seed=seed + 2, sigma_pos=noise[0], sigma_rot=noise[1])
        sim_u = S.simulate(robot, n_robots=R, q=q_uni, x_true=sim.x_true, q_val=sim.q_val[0], seed=seed + 3,
                           sigma_pos=noise[0], sigma_rot=noise[1])
        w_sp, w_sr = (sp, sr)
        q, meas = jnp.asarray(sim.q), jnp.asarray(sim.measured)
        meths = {
            "elimination": lambda: el.solve_batch(robot, q, meas, w_sp, w_sr, plan=plan, literal=False, max_steps=20),
            "elim. stacked (diag.)": lambda: el.solve_batch(robot, q, meas, w_sp, w_sr, plan=plan, stacked=True,
                                                            max_steps=20),
            "elimination-literal": lambda: el.solve_batch(robot, q, meas, w_sp, w_sr, plan=plan, literal=True),
            "gn (same poses)": lambda: _solve_batch(robot, q, meas, jnp.float64(w_sp), jnp.float64(w_sr), method="gn",
                                                    free=tuple(ident.base), m=len(names), position_only=False,
                                                    base=False, tool=False, rtol=1e-8, atol=1e-10, max_steps=50),
            "gn (uniform poses)": lambda: _solve_batch(robot, jnp.asarray(sim_u.q), jnp.asarray(sim_u.measured),
                                                       jnp.float64(w_sp), jnp.float64(w_sr), method="gn",
                                                       free=tuple(ident_uni.base), m=len(names), position_only=False,
                                                       base=False, tool=False, rtol=1e-8, atol=1e-10, max_steps=50),
        }
        print(f"\n-- {label}")
        print(f"{'method':>22s} {'conv':>8s} {'steps':>5s} {'par rms mm':>11s} {'par rms rad':>11s} "
              f"{'par max':>9s} {'val rms mm (median / p95)':>27s} {'time ms':>8s} {'compile s':>9s}")
        for meth, fn in meths.items():
            first, runs = timed(fn, repeats=repeats)
            x, ok, steps = fn()
            med = statistics.median(runs)
            pe = param_err(x, sim.x_true, ident_uni if "uniform" in meth else ident, names)
            v = val_rms(robot, x, sim.q_val, sim.true_val)
            v = np.where(np.isfinite(v), v, np.inf)
            print(f"{meth:>22s} {int(np.sum(ok)):4d}/{R:<3d} {int(np.max(steps)):5d} {pe['rms_mm']:11.3g} "
                  f"{pe['rms_rad']:11.3g} {pe['max_abs']:9.2g} {np.median(v):13.3g} / {np.percentile(v, 95, method='higher'):9.3g}"
                  f" {med * 1e3:8.1f} {max(first - med, 0.0):9.2f}")
            rows.append((name, label, meth, med))
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--robot", nargs="*", default=["paper-6r", "puma560", "ur5"])
    ap.add_argument("--robots", type=int, default=200)
    ap.add_argument("--pairs", type=int, default=4)
    ap.add_argument("--abs", type=int, default=2)
    ap.add_argument("--sigma-pos", type=float, default=0.02)
    ap.add_argument("--sigma-rot", type=float, default=2e-5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args()
    print(machine())
    print("compile s = first call minus the warm median (0 when the first call was no slower); only the first scenario's "
          "compile is real (later ones reuse it)")
    for name in a.robot:
        run(name, a.robots, a.pairs, a.abs, a.sigma_pos, a.sigma_rot, a.seed, a.repeats)


if __name__ == "__main__":
    main()
