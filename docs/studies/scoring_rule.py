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
(:data:`jaxcal.calibration._selection.PRUNE_SE`: 0, jaxcal's, the sparsest within 1 % of the best
number dropped; 0.5 and 1 more; and jaxcal's pruning before, along the order of a fit on all of
today's poses, :func:`prune_along_all`), and that of two fixed candidates pruned as jaxcal prunes
its choice. All on the problem linearised at the frames-only fit, as the
selection itself runs.

    python docs/studies/scoring_rule.py > docs/studies/scoring_rule.txt
"""

import dataclasses

import numpy as np
from scipy.stats import spearmanr

import jaxcal
from jaxcal.calibration import _selection as selection
from jaxcal.calibration import _workflow as workflow
from jaxcal.calibration._options import make_options
from jaxcal.measurements import franka_csv_path

CUTS, SEED, FOLDS = 60, 11, 5
PRUNE_SE = (0.0, 0.5, 1.0)
BEFORE = "along all poses' order, 0.5 (before)"
"""The pruning jaxcal used before (:func:`prune_along_all`), beside the PRUNE_SE values."""
FIXED = ("all, prior 1 mm", "all, prior 3 mm")
"""Candidates also pruned on their own, whatever the rule chooses."""


def data_sets():
    tiago = jaxcal.load_robot("jaxcal/data/tiago_mocap/tiago_arm.urdf")
    yield "TIAGo (4 points)", tiago, jaxcal.read_measurements("jaxcal/data/tiago_mocap/training.csv", tiago)
    panda = jaxcal.preset("panda")
    yield "Franka Panda (poses)", panda, jaxcal.read_measurements(franka_csv_path(), panda, length_unit="m")


def problem(robot, meas, **options):
    """``calibrate_data``'s problem (its stages, :mod:`jaxcal.calibration._workflow`): the outliers
    its first detection finds left out (unless ``keep_outliers``), linearised at the frames-only fit
    of the other poses and weighted as the workflow weighs it (:func:`_weighed`); ``(p, lin, J)``.
    Not its detection again at a lower noise nor its second look (neither changes the outliers of
    the bundled data sets)."""
    p = workflow._prepare(robot, meas, make_options(None, options, camera_auto=True), None)
    if not p.opts.keep_outliers:
        det = workflow._outliers_found(p, workflow._frames(p))
        p = dataclasses.replace(p, valid=~det.flags[0])
    fr = workflow._weighed(p, workflow._frames(p))
    lin, J = workflow._linear(p, fr.member(-1), fr.sig[[-1]])
    return p, lin, np.asarray(J)


def prune_along_all(lin, rule, free, prior, prunable, prune_se=0.5):
    """The pruning jaxcal used before (:func:`jaxcal.calibration._selection.prune`'s signature):
    every number dropped scored by the rule's folds along the order of a fit on *all* the rule's
    poses, held-out ones included, and the sparsest within ``prune_se`` standard errors kept."""
    free, prior, prunable = np.array(free, bool), np.asarray(prior, float), np.asarray(prunable, bool)
    start = float(selection.score(lin, rule, free[None], prior[None])[0])
    path, ts = [(free, -1, np.nan, start)], []
    while True:
        x = selection.solve(rule.A_all[None], rule.b_all[None], free[None], prior[None])[0, 0]
        se = selection.standard_errors(lin, rule, free, prior, x)
        t = {int(j): (abs(x[j]) / se[j] if se[j] > 0 else np.inf) for j in np.flatnonzero(free & prunable)}
        ts.append(t)
        if not t:
            break
        j = min(t, key=t.get)
        free = free.copy()
        free[j] = False
        path.append((free, j, t[j], float(selection.score(lin, rule, free[None], prior[None])[0])))
    scores = np.array([p[3] for p in path])
    best = int(np.nanargmin(scores))
    _, err = selection.score_error(lin, rule, path[best][0], prior)
    limit = scores[best] + max(prune_se * err, selection.PRUNE_TOLERANCE * scores[best])
    k = max(i for i in range(len(path)) if scores[i] <= limit)
    return path[k][0], tuple((j, t, s) for _, j, t, s in path[1 : k + 1]), ts[k]


def tomorrow_error(lin, today, tomorrow, free, prior):
    x = selection.fit(lin, today[None].astype(float), free, prior)[:, 0]
    e = selection.errors_mm(lin, x, np.flatnonzero(tomorrow))
    return np.sqrt(np.nanmean(e**2, axis=(1, 2)))


def cut(q, valid, rng):
    """One pseudo-session: ``(today, tomorrow)`` among the ``valid`` poses."""
    moving = [j for j in range(q.shape[1]) if np.ptp(q[:, j]) > 1e-9]
    j, hi = moving[rng.integers(len(moving))], bool(rng.integers(2))
    lim = np.quantile(q[:, j], 0.8 if hi else 0.2)
    beyond = q[:, j] > lim if hi else q[:, j] < lim
    tomorrow = (beyond | (rng.uniform(size=len(q)) < 0.2)) & valid
    return ~tomorrow & valid, tomorrow


def study(name, robot, meas, rng):
    p, lin, J = problem(robot, meas)
    names = [c.name for c in p.candidates]
    q, K = np.asarray(p.q), len(p.q)
    rules = ("K-fold", "K-fold + range ends", "K-fold + range ends, one-SE (jaxcal)")
    rows, truths, pruned = {r: [] for r in rules}, [], {v: [] for v in PRUNE_SE + (BEFORE,)}
    fixed = {names.index(n): [] for n in FIXED}
    for _ in range(CUTS):
        today, tomorrow = cut(q, p.valid, rng)
        seed = int(rng.integers(1 << 30))
        for v in PRUNE_SE + (BEFORE,):  # the workflow's selection (stage 4) on today's poses
            keep = selection.PRUNE_SE, selection.prune
            if v == BEFORE:
                selection.prune = prune_along_all
            else:
                selection.PRUNE_SE = v
            sel = workflow._select(p, lin, J, today, seed)
            selection.PRUNE_SE, selection.prune = keep
            free, prior, ch = sel.free, sel.priors, sel.choice
            pruned[v].append(tomorrow_error(lin, today, tomorrow, ch.free[None], prior[ch.index][None])[0])
        truth = tomorrow_error(lin, today, tomorrow, free, prior)
        truths.append(truth)
        rule = selection.Rule.of(lin, q, today, FOLDS, seed)
        a, b = selection.score_parts(lin, rule, free, prior)
        mixed = np.sqrt(0.5 * a**2 + 0.5 * b**2)
        for r, sc, c in zip(rules, (a, mixed, mixed), (int(np.nanargmin(a)), int(np.nanargmin(mixed)), ch.index)):
            rows[r].append((truth[c], truth[c] - np.nanmin(truth), spearmanr(sc, truth).statistic))
        penalised = np.zeros(lin.m, bool)
        penalised[: p.layout.n_kin] = True
        penalised[list(p.layout.compliances)] = True
        for c in fixed:
            kept = selection.prune(lin, rule, free[c], prior[c], penalised)[0]
            fixed[c].append(tomorrow_error(lin, today, tomorrow, kept[None], prior[c][None])[0])
    print(
        f"\n{name}: {K} poses ({int((~p.valid).sum())} outliers left out), {len(names)} candidates, {CUTS} cuts "
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
        print(f"{v if v == BEFORE else f'{v:g}':>40s} {np.mean(e):28.3f}")
    print(f"{f'candidate, pruned (PRUNE_SE {selection.PRUNE_SE:g})':>40s} {'tomorrow RMS (mm)':>28s}")
    for c, e in fixed.items():
        print(f"{names[c]:>40s} {np.mean(e):28.3f}")


def run(study):
    """``study(name, robot, meas, rng)`` on each data set, one seeded stream of cuts."""
    rng = np.random.default_rng(SEED)
    for name, robot, meas in data_sets():
        study(name, robot, meas, rng)


if __name__ == "__main__":
    run(study)
