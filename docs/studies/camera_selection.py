"""Franka with ``--camera-model auto``: would another way of choosing predict a later session better?

The nested held-out error of ``--camera-model auto`` on the Franka data stays at the no-camera
model's (docs/franka.md), while an explicit ``quadratic`` camera model predicts new postures among
the training ones better and postures beyond the training ranges worse. This study asks whether
a change to how the candidates are chosen or pruned, or a further candidate, would predict a later
session better, on the pseudo-sessions of ``docs/studies/scoring_rule.py`` (same cuts: "tomorrow"
is the poses beyond one end of one joint's range, its lowest or highest 20 %, and a random fifth
of the others; "today" the rest). Each way chooses on today's poses only, the model it chooses is
fitted on all of today and scored on tomorrow, on the problem linearised at the frames-only fit
exactly as ``calibrate_data`` builds it (outliers left out).

Ways compared (each a full selection: score, one-SE choice, pruning):

- **jaxcal**: as ``calibrate_data`` runs it (camera unknowns free, not pruned);
- **camera under the prior**: the camera unknowns held by the candidate's physically scaled prior
  (their lever: RMS displacement of the reported position per unit);
- **camera pruned**: the camera unknowns pruned like the kinematic parameters;
- **prune every candidate**: every candidate pruned, the lowest pruned score chosen;
- **prune by score**: from the chosen candidate, drop at each step the parameter whose removal
  scores best (backward stepwise on the score), instead of the least significant;
- **+ joint harmonics**: candidates with a once-per-turn joint angle error ``a_i sin q_i + b_i cos
  q_i`` per joint (an eccentric encoder or gear), under the same prior.

The best candidate of each cut (known only afterwards) gives the "oracle" line.

    python docs/studies/camera_selection.py > docs/studies/camera_selection.txt
"""

from collections import Counter

import numpy as np
from scoring_rule import problem

import jaxcal
from jaxcal.calibration import _selection as selection
from jaxcal.calibration._single import prior_of
from jaxcal.measurements import franka_csv_path
from jaxcal.solvers import PIN

CUTS, SEED, FOLDS = 60, 11, 5


def candidates(p, lever, camera_prior: bool):
    """Free sets and prior weights of the workflow's candidates (``lever`` per parameter)."""
    cams = list(p.layout.cameras)
    full = np.stack([prior_of(p.layout, p.ident, c, lever=lever) for c in p.candidates])
    free = full < PIN
    prior = np.where(free, full, 0.0)
    if camera_prior:
        for i, c in enumerate(p.candidates):
            prior[i, cams] = np.where(free[i, cams], c.prior_weight(1.0) * lever[cams], 0.0)
    return free, prior


def prunable(p, camera: bool):
    out = np.zeros(p.layout.size, bool)
    out[: p.layout.n_kin] = True
    out[list(p.layout.compliances)] = True
    out[list(p.layout.cameras)] = camera
    return out


def with_harmonics(p, lin, J, free, prior, pen):
    """The problem with two columns per joint (offset column times sin q and cos q), and the
    ``all`` candidates of the no-camera and quadratic models with them added under their prior."""
    q = np.asarray(p.q)
    names = p.layout.names()
    off = [names.index(f"theta{j + 1}") for j in range(q.shape[1])]
    cols = [(i, f(q[:, j])) for j, i in enumerate(off) for f in (np.sin, np.cos)]
    Jx = np.concatenate([J, np.stack([J[:, :, i] * s[:, None] for i, s in cols], -1)], -1)
    lin2 = selection.Linear(
        np.concatenate([lin.J, np.stack([lin.J[:, :, i] * s[:, None] for i, s in cols], -1)], -1),
        lin.r, lin.seen, lin.pos_scale, lin.n_points,
    )  # fmt: skip
    lev = selection.lever(Jx[p.valid], p.n_points)[lin.m :]
    F, P, C = [], [], []
    for i, c in enumerate(p.candidates):
        F.append(np.r_[free[i], np.zeros(len(cols), bool)])
        P.append(np.r_[prior[i], np.zeros(len(cols))])
        C.append(c.complexity)
        if c.camera in ("none", "quadratic") and c.name.startswith("all") and c.ridge_mm is not None:
            F.append(np.r_[free[i], np.ones(len(cols), bool)])
            P.append(np.r_[prior[i], c.prior_weight(1.0) * lev])
            C.append((c.complexity[0] + 2000, c.complexity[1]))
    return lin2, np.array(F), np.array(P), C, np.r_[pen, np.ones(len(cols), bool)]


def prune_by_score(lin, rule, free, prior, pen):
    """Backward stepwise on the score, the sparsest within :data:`PRUNE_SE` of the path's best."""
    f = free.copy()
    path = [(f, float(selection.score(lin, rule, f[None], prior[None])[0]))]
    while (drop := np.flatnonzero(f & pen)).size:
        F = np.repeat(f[None], drop.size, 0)
        F[np.arange(drop.size), drop] = False
        s = selection.score(lin, rule, F, np.repeat(prior[None], drop.size, 0))
        k = int(np.nanargmin(s))
        f = F[k]
        path.append((f, float(s[k])))
    s = np.array([v for _, v in path])
    b = int(np.argmin(s))
    limit = s[b] + max(selection.PRUNE_SE * selection.score_error(lin, rule, path[b][0], prior)[1], 0.01 * s[b])
    return path[max(i for i in range(len(path)) if s[i] <= limit)][0]


def main():
    panda = jaxcal.preset("panda")
    p, lin, J = problem(panda, jaxcal.read_measurements(franka_csv_path(), panda, length_unit="m"), camera="auto")
    q, clean = np.asarray(p.q), p.valid
    lever = selection.lever(J[clean], p.n_points)
    complexity = [c.complexity for c in p.candidates]
    names = [c.name for c in p.candidates]
    free, prior = candidates(p, lever, camera_prior=False)
    free_c, prior_c = candidates(p, lever, camera_prior=True)
    pen, pen_c = prunable(p, False), prunable(p, True)
    lin2, F2, P2, C2, pen2 = with_harmonics(p, lin, J, free, prior, pen)
    moving = [j for j in range(q.shape[1]) if np.ptp(q[:, j]) > 1e-9]
    rng = np.random.default_rng(SEED)
    out, chosen, oracle, each = {}, Counter(), [], []

    for _ in range(CUTS):
        j, hi = moving[rng.integers(len(moving))], bool(rng.integers(2))
        lim = np.quantile(q[:, j], 0.8 if hi else 0.2)
        beyond = q[:, j] > lim if hi else q[:, j] < lim
        tomorrow = (beyond | (rng.uniform(size=len(q)) < 0.2)) & clean
        today = ~tomorrow & clean
        seed = int(rng.integers(1 << 30))

        def error(L, f, pr):
            x = selection.fit(L, today[None].astype(float), np.atleast_2d(f), np.atleast_2d(pr))[:, 0]
            e = selection.errors_mm(L, x, np.flatnonzero(tomorrow))
            return np.sqrt(np.nanmean(e**2, axis=(1, 2)))

        rule = selection.Rule.of(lin, q, today, FOLDS, seed)
        every = error(lin, free, prior)
        each.append(every)
        oracle.append(np.nanmin(every))
        for name, fr_, pr_, pn in (
            ("jaxcal", free, prior, pen),
            ("camera under the prior", free_c, prior_c, pen),
            ("camera pruned", free, prior, pen_c),
        ):
            ch = selection.select(lin, rule, fr_, pr_, complexity, pn)
            out.setdefault(name, []).append(error(lin, ch.free, pr_[ch.index])[0])
            if name == "jaxcal":
                chosen[names[ch.index]] += 1
                out.setdefault("prune by score", []).append(
                    error(lin, prune_by_score(lin, rule, free[ch.index], prior[ch.index], pen), prior[ch.index])[0]
                )
        pruned = []
        for i in range(len(free)):
            s = selection.score(lin, rule, free[i][None], prior[i][None])[0]
            if np.isfinite(s):
                kept, dropped, _ = selection.prune(lin, rule, free[i], prior[i], pen)
                pruned.append((dropped[-1][2] if dropped else float(s), i, kept))
        s, i, kept = min(pruned, key=lambda v: v[0])
        out.setdefault("prune every candidate", []).append(error(lin, kept, prior[i])[0])
        rule2 = selection.Rule.of(lin2, q, today, FOLDS, seed)
        ch = selection.select(lin2, rule2, F2, P2, C2, pen2)
        out.setdefault("+ joint harmonics", []).append(error(lin2, ch.free, P2[ch.index])[0])

    print(f"Franka Panda (poses), camera auto: {len(q)} poses ({int((~clean).sum())} outliers left out), "
          f"{len(names)} candidates, {CUTS} cuts")  # fmt: skip
    print(f"{'way of choosing':>40s} {'tomorrow RMS (mm)':>18s} {'regret (mm)':>12s}")
    for name, v in out.items():
        print(f"{name:>40s} {np.mean(v):18.3f} {np.mean(np.array(v) - oracle):12.3f}")
    print(f"{'oracle (best candidate of each cut)':>40s} {np.mean(oracle):18.3f}")
    print("\njaxcal's choices:", ", ".join(f"{n} ({k})" for n, k in chosen.most_common()))
    each = np.array(each)
    print(f"\n{'candidate':>50s} {'mean tomorrow RMS (mm)':>23s} {'best in cuts':>12s}")
    wins = np.bincount(np.nanargmin(each, 1), minlength=len(names))
    for i, n in enumerate(names):
        if not n.startswith(("frames", "offsets")):
            print(f"{n:>50s} {np.nanmean(each[:, i]):23.3f} {wins[i]:12d}")


if __name__ == "__main__":
    main()
