"""Where the selection's problem is linearised: at the frames-only fit, or again at the fit.

``calibrate_data`` scores its candidates on the problem linearised at the frames-only fit of all
poses. When the linear model misses the chosen model's final weighted residual by more than
:data:`jaxcal.calibration._workflow.RELINEARISE` of it, the selection and the held-out fits are
made again on the problem linearised at that fit. The study prints that share (the gap) on the
bundled data, and on a simulated Panda (full poses, 0.02 mm and 2e-5 rad noise, base and tool
unknown) whose DH errors are the simulator's default scale times 1, 2 and 4: the held-out figure
and the error on 40 new poses of the true arm, with the selection made at the frames-only fit
alone and with the rule.

    python docs/studies/relinearisation.py > docs/studies/relinearisation.txt
"""

import numpy as np

import jaxcal
from jaxcal.calibration import _workflow as workflow
from jaxcal.kinematics import fk
from jaxcal.measurements import franka_csv_path
from jaxcal.simulation import simulate

RULE = workflow.RELINEARISE


def gaps(robot, meas, **kw) -> list:
    """The gap of every linearisation ``calibrate_data`` makes on these data."""
    seen, measure = [], workflow._linear_gap

    def spy(*a):
        seen.append(measure(*a))
        return seen[-1]

    workflow._linear_gap = spy
    try:
        jaxcal.calibrate_data(robot, meas, **kw)
    finally:
        workflow._linear_gap = measure
    return seen


def transform(rng, scale):
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.normal(size=3) * scale
    return T


def panda(factor: float):
    """Simulated Panda data with DH errors ``factor`` times the simulator's default scale."""
    rng = np.random.default_rng(20221)
    r = jaxcal.preset("panda")
    x_dh = np.asarray(simulate(r, seed=5).x_true[0])[: 4 * r.n_joints] * factor
    B, X = transform(rng, 500.0), transform(rng, 100.0)
    truth = r.replace(base=B, tool=np.asarray(r.tool) @ X)
    sim = simulate(truth, n_poses=60, n_val=40, seed=0, x_true=np.r_[x_dh, np.zeros(12)], sigma_pos=0.02,
                   sigma_rot=2e-5, base=True, tool=True)  # fmt: skip
    angles = np.abs(x_dh.reshape(-1, 4)[:, [0, 3]]).max()
    return r, jaxcal.Measurements(sim.q[0], sim.measured[0]), sim, np.degrees(angles)


def main():
    tiago = jaxcal.load_robot("jaxcal/data/tiago_mocap/tiago_arm.urdf")
    print(f"gap at the frames-only fit (rule: linearised again above {RULE:g})")
    data = jaxcal.read_measurements("jaxcal/data/tiago_mocap/training.csv", tiago)
    print(f"  TIAGo, 4 points: {gaps(tiago, data)[0]:.3f}")
    r = jaxcal.preset("panda")
    franka = jaxcal.read_measurements(franka_csv_path(), r, length_unit="m")
    print(f"  Franka, poses: {gaps(r, franka)[0]:.3f}")
    print(f"  Franka, poses, --camera-model auto: {gaps(r, franka, camera='auto')[0]:.3f}")
    quadratic = ", ".join(f"{g:.3g}" for g in gaps(r, franka, camera="quadratic"))
    print(f"  Franka, poses, --camera-model quadratic: {quadratic}")
    print()
    print("simulated Panda: held-out (nested) and true error on 40 new poses, mm")
    head = ("DH errors", "largest angle (deg)", "gaps", "linearised once", "with the rule")
    print(" ".join(f"{h:>{w}s}" for h, w in zip(head, (10, 20, 16, 24, 24))))
    for factor in (1.0, 2.0, 4.0):
        robot, meas, sim, deg = panda(factor)
        cells = []
        for rule in (np.inf, RULE):
            workflow.RELINEARISE = rule
            try:
                res = jaxcal.calibrate_data(robot, meas, folds=3)
                seen = gaps(robot, meas, folds=3) if rule == RULE else []
            finally:
                workflow.RELINEARISE = RULE
            err = np.linalg.norm(np.asarray(fk(res.robot, sim.q_val[0]))[:, :3, 3] - sim.true_val[0][:, :3, 3], axis=1)
            cells.append(f"{res.report['heldout_rms_mm']:.4f} / {np.sqrt(np.mean(err**2)):.4f}")
        print(f"{factor:>9g}x {deg:20.2f} {', '.join(f'{g:.3g}' for g in seen):>16s} {cells[0]:>24s} {cells[1]:>24s}")


if __name__ == "__main__":
    main()
