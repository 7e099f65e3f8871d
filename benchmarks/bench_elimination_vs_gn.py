"""The paper's joint-by-joint elimination (robust and literal) against Gauss–Newton on the same
measured poses: accuracy and time.

    python benchmarks/bench_elimination_vs_gn.py [--robot paper-6r puma560 ur5] [--robots 100]
        [--pairs 4] [--abs 2] [--repeats 5]

Per arm: ``R`` true robots (default error scales, :func:`jaxcal.simulation.error_scales`), one
elimination design (:func:`jaxcal.solvers.design_poses`, ``2 (N-1) pairs + abs`` poses)
measured with noise; every method sees exactly these poses (the same measurement budget). GN
also runs on as many uniformly drawn poses (its natural design), for reference. Three
scenarios: noise-free with the design's unidentifiable parameters' truth 0, noise-free with all
parameters perturbed, and noisy.

Reported: parameter error on the identifiable set (estimate vs ``C @ x_true``, the first-order
combination each base parameter estimates, :mod:`jaxcal.identifiability`), inspection position
RMS on 50 other poses against the true robot, convergence, and the time of one compiled call
over all robots (median of warm calls; compile apart). The solvers are timed bare, both vmapped
over the robots in one call: :func:`jaxcal.solvers.eliminate_batch` and
:func:`jaxcal.solvers.fit`, the Gauss–Newton solve inside :func:`jaxcal.calibrate_batch`.
"""

from __future__ import annotations

import argparse
import statistics

import jax
import jax.numpy as jnp
import numpy as np
from _util import compile_s, print_machine, timed

import jaxcal
from jaxcal.calibration import identify
from jaxcal.error_model import perturb
from jaxcal.model import Layout, Model, row_weights
from jaxcal.simulation import error_scales, sample_poses
from jaxcal.solvers import design_poses, eliminate_batch, fit, make_plan


def val_rms(robot, x, q_val, true_val):
    """Inspection position RMS per robot (mm)."""
    T = jax.jit(jax.vmap(lambda xx, qv: jaxcal.fk(perturb(robot, xx), qv)))(jnp.asarray(x), jnp.asarray(q_val))
    d = np.linalg.norm(np.asarray(T)[..., :3, 3] - true_val[..., :3, 3], axis=-1)
    return np.sqrt(np.mean(d**2, axis=-1))


def param_err(x, x_true, ident):
    C = ident.combination_matrix
    e = np.asarray(x)[:, list(ident.base)] - np.asarray(x_true) @ C.T
    rad = np.array([ident.names[j].startswith(("theta", "alpha")) for j in ident.base])
    rms = np.sqrt(np.mean(e**2, axis=0))
    return {
        "rms_mm": float(np.sqrt(np.mean(rms[~rad] ** 2))),
        "rms_rad": float(np.sqrt(np.mean(rms[rad] ** 2))),
        "max_abs": float(np.abs(e).max()),
    }


def gn_batch(robot, free, sp, sr):
    """Vmapped Gauss–Newton of every robot's data (DH errors, base and tool known)."""
    layout, model = Layout.of(robot), Model(robot.stripped())
    w = row_weights(layout, sp, sr)
    one = lambda q, t: fit(model, layout, tuple(free), q, t, weights=w, method="gn")
    f = jax.jit(jax.vmap(one))

    def call(q, meas):
        s = f(q, meas)
        return s.x, s.converged, s.steps

    return call


def run(name, R, pairs, n_abs, sp, sr, seed, repeats):
    robot = jaxcal.preset(name)
    qd = np.asarray(design_poses(jax.random.PRNGKey(seed), robot, n_pairs=pairs, n_abs=n_abs))
    K = qd.shape[0]
    plan = make_plan(robot, qd)
    ident = identify(robot, qd, estimate_base=False, estimate_tool=False)
    q_uni = np.asarray(sample_poses(jax.random.PRNGKey(seed + 1), robot, (K,)))
    ident_uni = identify(robot, q_uni, estimate_base=False, estimate_tool=False)
    print(
        f"\n=== {name}: {R} robots, design {pairs} pairs/step + {n_abs} abs = {K} poses, noise {sp} mm / {sr} rad ==="
    )
    print(plan.report())
    print(
        "GN base set on the same poses fixes:",
        ", ".join(ident.fixed_names) or "none",
        "|",
        "; ".join(ident.combinations) or "",
    )
    if set(plan.fixed) != set(ident.fixed):
        print("NOTE: elimination and GN hold different parameters fixed")
    scales = error_scales(robot)
    scales0 = scales.copy()
    scales0[list(plan.fixed)] = 0.0
    gn_same, gn_uni = gn_batch(robot, ident.base, sp, sr), gn_batch(robot, ident_uni.base, sp, sr)
    elim = lambda q, meas, **kw: eliminate_batch(robot, q, meas, sp, sr, plan=plan, **kw)
    for label, sc, noise in (
        ("noise-free, fixed params' truth = 0", scales0, (0.0, 0.0)),
        ("noise-free, all params perturbed", scales, (0.0, 0.0)),
        (f"noisy {sp} mm / {sr} rad", scales, (sp, sr)),
    ):
        sim = jaxcal.simulate(robot, n_robots=R, q=qd, scales=sc, seed=seed + 2, sigma_pos=noise[0], sigma_rot=noise[1])
        sim_u = jaxcal.simulate(
            robot,
            n_robots=R,
            q=q_uni,
            x_true=sim.x_true,
            q_val=sim.q_val[0],
            seed=seed + 3,
            sigma_pos=noise[0],
            sigma_rot=noise[1],
        )
        q, meas = jnp.asarray(sim.q), jnp.asarray(sim.measured)
        qu, measu = jnp.asarray(sim_u.q), jnp.asarray(sim_u.measured)
        meths = {  # the weights are the noisy scenario's in every scenario: one compiled solve each
            "elimination": lambda: elim(q, meas, max_steps=20),
            "elim. stacked (diag.)": lambda: elim(q, meas, stacked=True, max_steps=20),
            "elimination-literal": lambda: elim(q, meas, literal=True),
            "gn (same poses)": lambda: gn_same(q, meas),
            "gn (uniform poses)": lambda: gn_uni(qu, measu),
        }
        print(f"\n-- {label}")
        print(
            f"{'method':>22s} {'conv':>8s} {'steps':>5s} {'par rms mm':>11s} {'par rms rad':>11s} "
            f"{'par max':>9s} {'val rms mm (median / p95)':>27s} {'time ms':>8s} {'compile s':>9s}"
        )
        med = {}
        for meth, fn in meths.items():
            (x, ok, steps), first, runs = timed(fn, repeats=repeats, result=True)
            med[meth] = statistics.median(runs)
            pe = param_err(x, sim.x_true, ident_uni if "uniform" in meth else ident)
            v = val_rms(robot, x, sim.q_val, sim.true_val)
            v = np.where(np.isfinite(v), v, np.inf)
            print(
                f"{meth:>22s} {int(np.sum(ok)):4d}/{R:<3d} {int(np.max(steps)):5d} {pe['rms_mm']:11.3g} "
                f"{pe['rms_rad']:11.3g} {pe['max_abs']:9.2g} {np.median(v):13.3g} / "
                f"{np.percentile(v, 95, method='higher'):9.3g} {med[meth] * 1e3:8.1f} "
                f"{compile_s(first, runs):9.2f}",
                flush=True,
            )
        gn = med["gn (same poses)"]
        print("time / gn (same poses): " + ", ".join(f"{m} {t / gn:.2f}x" for m, t in med.items()))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--robot", nargs="*", default=["paper-6r", "puma560", "ur5"])
    ap.add_argument("--robots", type=int, default=100)
    ap.add_argument("--pairs", type=int, default=4)
    ap.add_argument("--abs", type=int, default=2)
    ap.add_argument("--sigma-pos", type=float, default=0.02)
    ap.add_argument("--sigma-rot", type=float, default=2e-5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args()
    print_machine()
    print(
        "compile s = first call minus the warm median (0 when the first call was no slower); only an arm's first "
        "scenario pays it (the later ones reuse the compiled solves)"
    )
    for name in a.robot:
        run(name, a.robots, a.pairs, a.abs, a.sigma_pos, a.sigma_rot, a.seed, a.repeats)


if __name__ == "__main__":
    main()
