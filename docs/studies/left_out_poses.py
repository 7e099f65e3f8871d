"""Does leaving out the poses the outlier detection flags predict a later session better?

On the simulated arm of ``docs/studies/simulated_sessions.py`` with non-geometric errors, the
default leaves out clean postures at the ends of the joint ranges, as far off in units of the
noise as the postures it leaves out of the bundled TIAGo data. Whether the real ones are
measurement faults or the arm's own behaviour there decides whether leaving them out helps. This
study asks the data, on the pseudo-sessions of ``docs/studies/scoring_rule.py`` (same cuts:
"tomorrow" is the poses beyond one end of one joint's range, its lowest or highest 20 %, and a
random fifth of the others; "today" the rest). The outliers are found on all poses by
``calibrate_data``'s detection with its model (``all`` and the compliances) under a prior of 0.3, 1,
3 or 10 mm (1 mm is the default, :data:`jaxcal.calibration._workflow.DETECTION_PRIOR_MM`), or none
are (``keep_outliers``). Each way's problem is its own (``scoring_rule.problem``: linearised at
the frames-only fit of the poses it keeps, in their noise); it leaves its outliers out of today,
chooses and prunes its model there as ``calibrate_data`` does, and is scored on tomorrow: on the
poses that no way flags (a model that fits faulty poses predicts the others worse), and on all
of tomorrow's poses (the faults included, which no model predicts).

    python docs/studies/left_out_poses.py > docs/studies/left_out_poses.txt
"""

import numpy as np
from scoring_rule import CUTS, cut, problem, run

from jaxcal.calibration import _selection as selection
from jaxcal.calibration import _workflow as workflow

DETECTION_PRIORS_MM = (0.3, 1.0, 3.0, 10.0)


def rms(lin, x, poses) -> float:
    e = selection.errors_mm(lin, x[None], np.flatnonzero(poses))
    return float(np.sqrt(np.nanmean(e**2)))


def study(name, robot, meas, rng):
    ways = {}
    for s in DETECTION_PRIORS_MM:
        workflow.DETECTION_PRIOR_MM, keep = s, workflow.DETECTION_PRIOR_MM
        try:
            ways[f"detection prior {s:g} mm"] = problem(robot, meas)
        finally:
            workflow.DETECTION_PRIOR_MM = keep
    ways["nothing left out"] = problem(robot, meas, keep_outliers=True)
    common = np.all([p.valid for p, _, _ in ways.values()], 0)
    p0 = ways["nothing left out"][0]
    out = {w: [] for w in ways}
    for _ in range(CUTS):
        _, tomorrow = cut(np.asarray(p0.q), p0.valid, rng)
        seed = int(rng.integers(1 << 30))
        for w, (p, lin, J) in ways.items():
            today = ~tomorrow & p.valid
            sel = workflow._select(p, lin, J, today, seed)  # calibrate_data's choice and pruning
            x = selection.fit(lin, today[None].astype(float), sel.choice.free[None], sel.priors[sel.choice.index][None])
            out[w].append((rms(lin, x[0, 0], tomorrow & common), rms(lin, x[0, 0], tomorrow)))
    print(f"\n{name}: {len(p0.q)} poses, {CUTS} cuts; {int(common.sum())} poses no way flags")
    print(f"{'way':>26s} {'file rows left out':>32s} {'tomorrow, unflagged (mm)':>25s} {'tomorrow, all (mm)':>19s}")
    for w, v in out.items():
        p = ways[w][0]
        rows = ", ".join(str(int(p.rows[k])) for k in np.flatnonzero(~p.valid)) or "-"
        m = np.mean(v, 0)
        print(f"{w:>26s} {rows:>32s} {m[0]:25.3f} {m[1]:19.3f}")


if __name__ == "__main__":
    run(study)
