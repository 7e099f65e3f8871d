"""Would a backlash term, as a candidate beside the compliances, predict a later session better?

A joint with backlash sits at one end of its play or the other, by the sign of the load on it:
``q_i + b_i sign(tau_i(q))``, ``tau_i`` the gravity moment of :func:`jaxcal.kinematics.gravity_moments`
(a unit weight at the tool) and ``b_i`` one unknown per joint whose moment changes sign over the
data (where it keeps one sign, the term is the joint's offset). Its identification column is the
joint offset's times ``sign(tau_i)``. This study adds those columns to the problem
``calibrate_data`` selects on (``scoring_rule.problem``: linearised at the frames-only fit, its
outliers left out) and the candidates ``all + backlash`` under a prior of 1 and 3 mm (the columns
under the same physically scaled prior) and none, on the pseudo-sessions of
``docs/studies/scoring_rule.py`` (same cuts).
It reports each candidate's mean tomorrow error and that of the model jaxcal's rule chooses (not
pruned) among the usual candidates and among them with the backlash ones.

    python docs/studies/backlash_candidate.py > docs/studies/backlash_candidate.txt
"""

import numpy as np
from scoring_rule import CUTS, FOLDS, cut, problem, run, tomorrow_error

from jaxcal.calibration import _selection as selection
from jaxcal.calibration import _workflow as workflow
from jaxcal.kinematics import gravity_moments

PRIORS_MM = (1.0, 3.0, None)


def backlash_columns(robot, p, lin, J):
    """``(weighted, unweighted)`` backlash columns of the loaded joints: the offset's times the sign
    of the gravity moment."""
    offset = "offset" if robot.convention == "joint" else "theta"
    sign = np.sign(np.asarray(gravity_moments(robot, p.q)))
    cols = [(p.layout.names().index(f"{offset}{i + 1}"), sign[:, i]) for i in range(robot.n_joints)]
    cols = [(j, s) for j, s in cols if (s > 0).any() and (s < 0).any()]  # else the offset's own column
    return tuple(np.stack([A[:, :, j] * s[:, None] for j, s in cols], -1) for A in (lin.J, J))


def study(name, robot, meas, rng):
    p, lin, J = problem(robot, meas)
    weighted, B = backlash_columns(robot, p, lin, J)
    lin2 = selection.Linear(np.concatenate([lin.J, weighted], -1), lin.r, lin.seen, lin.pos_scale, lin.n_points)
    names, n = [c.name for c in p.candidates], B.shape[-1]
    labels = names + ["all + backlash" + ("" if s is None else f", prior {s:g} mm") for s in PRIORS_MM]
    q = np.asarray(p.q)
    truths, chosen = [], {"usual candidates": [], "with the backlash ones": []}
    for _ in range(CUTS):
        today, tomorrow = cut(q, p.valid, rng)
        seed = int(rng.integers(1 << 30))
        sel = workflow._select(p, lin, J, today, seed)  # calibrate_data's candidates and choice
        lever = selection.lever(B[today], p.n_points)
        F = list(np.concatenate([sel.free, np.zeros((len(names), n), bool)], 1))
        P = list(np.concatenate([sel.priors, np.zeros((len(names), n))], 1))
        C = [c.complexity for c in p.candidates]
        for s in PRIORS_MM:
            i = names.index("all" if s is None else f"all, prior {s:g} mm")
            F.append(np.r_[sel.free[i], np.ones(n, bool)])
            P.append(np.r_[sel.priors[i], np.zeros(n) if s is None else lever / s])
            C.append((C[i][0] + 2000, C[i][1]))
        F, P = np.array(F), np.array(P)
        usual = tomorrow_error(lin, today, tomorrow, sel.free, sel.priors)  # as scoring_rule's
        truth = np.r_[usual, tomorrow_error(lin2, today, tomorrow, F[len(names) :], P[len(names) :])]
        truths.append(truth)
        rule = selection.Rule.of(lin2, q, today, FOLDS, seed)
        every = selection.select(lin2, rule, F, P, C, np.zeros(lin2.m, bool))  # unpruned: nothing prunable
        chosen["usual candidates"].append(truth[sel.choice.index])
        chosen["with the backlash ones"].append(truth[every.index])
    t = np.array(truths)
    print(f"\n{name}: {len(q)} poses ({int((~p.valid).sum())} outliers left out), {CUTS} cuts")
    print(f"{'candidate':>40s} {'mean tomorrow RMS (mm)':>24s}")
    for i, label in enumerate(labels):
        print(f"{label:>40s} {np.nanmean(t[:, i]):24.3f}")
    print(f"{'one-SE choice (not pruned) among':>40s} {'tomorrow RMS (mm)':>24s}")
    for way, v in chosen.items():
        print(f"{way:>40s} {np.mean(v):24.3f}")


if __name__ == "__main__":
    run(study)
