"""Does the scoring rule predict the error on a later session better than plain K-fold?

Pseudo-sessions cut from one real data set: "tomorrow" is the poses beyond one end of one
joint's range (its lowest or highest 20 %) together with a random fifth of the others, as a
later session repeats some postures, adds new ones and goes beyond the training ranges;
"today" is the rest. On today's poses every candidate of ``--params auto`` is scored by plain
K-fold and by jaxcal's score (K-fold and range-end folds, :mod:`jaxcal.calibration._selection`),
then fitted on all of today and scored on tomorrow. A rule chooses the lowest score, or (jaxcal's
choice) the simplest candidate within one standard error of it. For each rule the study reports,
over many cuts, the mean tomorrow error of the model it chooses, the regret (that error minus
the best candidate's), and the rank correlation of its score with the tomorrow error; then each
candidate's mean tomorrow error, and the tomorrow error of jaxcal's choice after its pruning
(:data:`jaxcal.calibration._selection.PRUNE_SE`: 0 is no pruning beyond 1 %, 0.5 jaxcal's, 1 the
full one-standard-error rule). All on the problem linearised at the frames-only fit, as the
selection itself runs.

    python docs/studies/scoring_rule.py > docs/studies/scoring_rule.txt
"""

import numpy as np
from scipy.stats import spearmanr

import jaxcal
from jaxcal.calibration import _selection as selection
from jaxcal.calibration._param_sets import parse_params
from jaxcal.calibration._single import make_layout, prior_of
from jaxcal.model import errors, jacobian
from jaxcal.solvers import PIN

CUTS, SEED, FOLDS = 60, 11, 5
PRUNE_SE = (0.0, 0.5, 1.0)


def data_sets():
    tiago = jaxcal.load_robot("jaxcal/data/tiago_mocap/tiago_arm.urdf")
    yield "TIAGo (4 points)", tiago, jaxcal.read_measurements("jaxcal/data/tiago_mocap/training.csv", tiago)
    panda = jaxcal.preset("panda")
    path = "jaxcal/data/franka_panda_camera/measurements.csv"
    yield "Franka Panda (poses)", panda, jaxcal.read_measurements(path, panda, length_unit="m")


def candidates(robot, meas):
    """The linearised problem and the auto candidates' free sets and priors (compliance included)."""
    opts = jaxcal.Options(compliance="auto")
    n_points = meas.n_points
    res = jaxcal.calibrate(robot, meas.q, meas.measured, params="frames")
    layout = make_layout(robot, opts, n_points, compliance=True)
    ref = res.model
    J = np.asarray(jacobian(ref, layout, meas.q))
    w = np.r_[np.full(3, 1 / res.sigma_pos_mm), np.full(3, 1 / res.sigma_rot_rad)] if n_points == 0 else None
    w = np.full(layout.rows, 1 / res.sigma_pos_mm) if w is None else w
    lin = selection.linearise(J, np.asarray(errors(ref, meas.q, meas.measured)), w, n_points)
    ident = jaxcal.calibration.identify(robot, meas.q, opts, n_points=n_points, compliance="yes")
    lever = selection.lever(J, n_points)
    cands = parse_params("auto", robot, compliance=True)
    full = np.stack([prior_of(layout, ident, c, lever=lever) for c in cands])
    return lin, cands, full < PIN, np.where(full < PIN, full, 0.0)


def tomorrow_error(lin, today, tomorrow, free, prior):
    x = selection.fit(lin, today[None].astype(float), free, prior)[:, 0]
    e = selection.errors_mm(lin, x, np.flatnonzero(tomorrow))
    return np.sqrt(np.nanmean(e**2, axis=(1, 2)))


def study(name, robot, meas, rng):
    lin, cands, free, prior = candidates(robot, meas)
    names, complexity = [c.name for c in cands], [c.complexity for c in cands]
    q, K = np.asarray(meas.q), len(meas.q)
    found = jaxcal.calibrate(robot, q, meas.measured, ridge_mm=1.0, compliance="yes").outliers
    clean = ~np.isin(np.arange(K), found)  # the poses calibrate_data would keep
    moving = [j for j in range(q.shape[1]) if np.ptp(q[:, j]) > 1e-9]
    rules = ("K-fold", "K-fold + range ends", "K-fold + range ends, one-SE (jaxcal)")
    rows, truths, pruned = {r: [] for r in rules}, [], {v: [] for v in PRUNE_SE}
    penalised = prior[[c.name for c in cands].index("all, prior 1 mm")] > 0
    for _ in range(CUTS):
        j, hi = moving[rng.integers(len(moving))], bool(rng.integers(2))
        lim = np.quantile(q[:, j], 0.8 if hi else 0.2)
        beyond = q[:, j] > lim if hi else q[:, j] < lim
        tomorrow = (beyond | (rng.uniform(size=K) < 0.2)) & clean
        today = ~tomorrow & clean
        truth = tomorrow_error(lin, today, tomorrow, free, prior)
        truths.append(truth)
        rule = selection.Rule.of(lin, q, today, FOLDS, int(rng.integers(1 << 30)))
        a, b = selection.score_parts(lin, rule, free, prior)
        mixed = np.sqrt(0.5 * a**2 + 0.5 * b**2)
        best = int(np.nanargmin(mixed))
        se = selection.score_error(lin, rule, free[best], prior[best])[1]
        picks = (int(np.nanargmin(a)), best, selection.choose(mixed, complexity, se))
        for r, s, c in zip(rules, (a, mixed, mixed), picks):
            rows[r].append((truth[c], truth[c] - np.nanmin(truth), spearmanr(s, truth).statistic))
        for v in PRUNE_SE:
            selection.PRUNE_SE, keep = v, selection.PRUNE_SE
            ch = selection.select(lin, rule, free, prior, complexity, penalised)
            selection.PRUNE_SE = keep
            pruned[v].append(tomorrow_error(lin, today, tomorrow, ch.free[None], prior[ch.index][None])[0])
    print(
        f"\n{name}: {K} poses ({len(found)} outliers left out), {len(names)} candidates, {CUTS} cuts "
        "(tomorrow: ~20 % beyond one range end + 20 % of the rest)"
    )
    print(f"{'rule':>40s} {'tomorrow RMS of choice (mm)':>28s} {'regret (mm)':>12s} {'rank correlation':>17s}")
    for r, v in rows.items():
        v = np.array(v)
        print(f"{r:>40s} {v[:, 0].mean():28.3f} {v[:, 1].mean():12.3f} {np.nanmean(v[:, 2]):17.3f}")
    t = np.array(truths)
    print(f"{'candidate':>40s} {'mean tomorrow RMS (mm)':>28s} {'best in cuts':>12s}")
    wins = np.bincount(np.nanargmin(t, 1), minlength=len(names))
    for i, n in enumerate(names):
        print(f"{n:>40s} {np.nanmean(t[:, i]):28.3f} {wins[i]:12d}")
    print(f"{'pruning of the choice (PRUNE_SE)':>40s} {'tomorrow RMS (mm)':>28s}")
    for v, e in pruned.items():
        print(f"{v:>40g} {np.mean(e):28.3f}")


def main():
    rng = np.random.default_rng(SEED)
    for name, robot, meas in data_sets():
        study(name, robot, meas, rng)


if __name__ == "__main__":
    main()
