"""A fit that is not a calibration is refused, whatever the robot's description: a DH or URDF
joint-frame change beyond its limit, a diverged fit, a camera unknown beyond 10 %, and a parameter
the data do not determine (a URDF joint frame's, or a camera's depth scale from poses all at one
distance from the target) are named rather than written."""

from pathlib import Path

import numpy as np
import pytest
from helpers import dh_fk
from scipy.spatial.transform import Rotation

import jaxcal
from jaxcal.calibration._plausibility import Thresholds, findings
from jaxcal.model import Layout

TIAGO = Path(__file__).resolve().parents[2] / "jaxcal" / "data" / "tiago_mocap"
LIMITS = Thresholds(residual_mm=10.0, rotation_deg=2.0, length_mm=30.0, angle_rad=np.radians(20.0), camera=0.1)
FIT = {"pos_rms_mm": 0.1, "rot_rms_deg": 0.01}


def _layouts():
    tiago = jaxcal.load_robot("jaxcal/data/tiago_mocap/tiago_arm.urdf")
    return {
        "joint frames": (Layout.of(tiago, base=True, tool=True, n_points=0), "x3", "rx4"),
        "dh": (Layout.of(jaxcal.preset("ur5"), base=True, tool=True, n_points=0), "a3", "alpha4"),
    }


def test_dh_changes_held_to_the_limits():
    layout, length, angle = _layouts()["dh"]
    names = layout.names()
    x = np.zeros(layout.size)
    x[names.index(length)] = 29.0
    x[names.index(angle)] = np.radians(19.0)
    assert findings(FIT, x, layout, LIMITS) == []
    x[names.index(length)] = -31.0
    x[names.index(angle)] = np.radians(21.0)
    found = " ".join(findings(FIT, x, layout, LIMITS))
    assert f"{length} changes by 31 mm" in found and "max_length_change_mm" in found
    assert f"{angle} changes by 21 deg" in found and "max_angle_change_deg" in found
    # a parameter that is not estimated is not judged
    assert findings(FIT, x, layout, LIMITS, free=[names.index("d2")]) == []


def test_joint_frames_held_to_the_limits_and_judged_by_what_the_data_determine():
    """A URDF joint frame's shifts and turns are held to the same limits as DH values (its base set
    is exchanged away from near twins: values beyond them write the links far from the arm), and
    its standard errors are judged, as every parameter's."""
    layout, length, angle = _layouts()["joint frames"]
    names = layout.names()
    x = np.zeros(layout.size)
    x[names.index(length)] = 29.0
    x[names.index(angle)] = np.radians(19.0)
    se = np.where(np.array(layout.units()) == "mm", 0.4, 0.004)
    assert findings(FIT, x, layout, LIMITS, se=se) == []
    x[names.index(length)] = 38.0
    x[names.index("offset3")] = np.radians(-21.0)
    found = " ".join(findings(FIT, x, layout, LIMITS, se=se))
    assert f"{length} changes by 38 mm" in found and "offset3 changes by 21 deg" in found
    x[:] = 0.0
    se[names.index(length)] = 31.0
    (found,) = findings(FIT, x, layout, LIMITS, se=se)
    assert f"do not determine {length} (31 mm)" in found


def test_a_urdf_arm_with_two_joint_columns_swapped_is_refused_naming_them():
    """The bundled TIAGo's 37 real postures with the columns of its last two joints exchanged: the
    joint-frame model fits them to 4.5 mm (1.5 mm as recorded) by turning the last origin half a
    turn; that value is judged, and the swap named."""
    rows = np.genfromtxt(TIAGO / "training.csv", delimiter=",", names=True)
    joints = ["torso_lift_joint"] + [f"arm_{i}_joint" for i in range(1, 8)]
    q = np.stack([rows[n] for n in joints], 1) * np.r_[1e3, np.ones(7)]  # the torso slides: mm inside
    points = np.stack([np.stack([rows[f"{c}{m}"] for c in "xyz"], -1) for m in range(1, 5)], 1) * 1e3
    q[:, [6, 7]] = q[:, [7, 6]]
    robot = jaxcal.load_robot(TIAGO / "tiago_arm.urdf")
    with pytest.warns(jaxcal.CalibrationWarning) as said:
        r = jaxcal.calibrate(robot, q, points)
    assert not r.plausible
    assert "joints 7 and 8 swapped ('arm_6_joint', 'arm_7_joint')" in str(said[-1].message)


def test_a_diverged_fit_is_never_plausible():
    layout, _, _ = _layouts()["dh"]
    x = np.zeros(layout.size)
    for stats, params in (({"pos_rms_mm": np.nan, "rot_rms_deg": 0.01}, x), (FIT, np.r_[np.nan, x[1:]])):
        assert findings(stats, params, layout, LIMITS) == [
            "the fit diverged: its residual or parameters are not finite numbers"
        ]


def test_camera_unknowns_and_undetermined_parameters():
    layout = Layout.of(jaxcal.preset("panda"), base=True, tool=True, n_points=0, camera="linear")
    names = layout.names()
    x = np.zeros(layout.size)
    x[names.index("camera_A_xz")] = 0.09
    se = np.full(layout.size, 1e-3)
    assert findings(FIT, x, layout, LIMITS, se=se) == []
    x[names.index("camera_A_xz")] = -0.2
    assert "camera_A_xz is -0.2, beyond +-0.1 (max_camera_change)" in " ".join(findings(FIT, x, layout, LIMITS))
    x[:] = 0.0
    se[names.index("tool_z")] = 31.0  # mm, beyond the 30 mm length limit
    se[names.index("camera_depth_scale")] = np.nan
    (found,) = findings(FIT, x, layout, LIMITS, se=se)
    assert "do not determine" in found and "tool_z (31 mm)" in found and "camera_depth_scale (nan)" in found
    assert "alpha" not in found


def _one_distance_poses(robot, dh, B, X, n, depth, rng):
    """``n`` configurations whose camera (``B A(q) X``) sees the target origin at exactly ``depth``
    mm along its optical axis: random joints 2..n, joint 1 found by bisection."""
    lo, hi = np.asarray(robot.q_limits).T

    def depth_of(q):
        T = dh_fk(dh, q, convention=robot.convention, base=B, tool=X)
        return -np.einsum("ki,ki->k", T[:, :3, 2], T[:, :3, 3])

    grid = np.linspace(lo[0], hi[0], 41)
    rest = rng.uniform(lo[1:], hi[1:], (4 * n, len(lo) - 1))
    z = depth_of(np.c_[np.tile(grid, len(rest)), np.repeat(rest, len(grid), 0)]).reshape(len(rest), -1) - depth
    cross = np.sign(z[:, :-1]) != np.sign(z[:, 1:])
    ok = np.flatnonzero(cross.any(1))[:n]
    assert len(ok) == n
    first = cross[ok].argmax(1)
    a, b, za = grid[first], grid[first + 1], z[ok, first]
    for _ in range(50):
        m = 0.5 * (a + b)
        zm = depth_of(np.c_[m, rest[ok]]) - depth
        same = np.sign(zm) == np.sign(za)
        a, za, b = np.where(same, m, a), np.where(same, zm, za), np.where(same, b, m)
    return np.c_[0.5 * (a + b), rest[ok]]


def test_a_camera_depth_scale_the_poses_cannot_determine_is_refused():
    """Hand-eye poses at one distance from the target: the depth scale trades exactly with the tool
    along the optical axis. Judged at the nominal robot it looks determined (its depths differ);
    at the solution it is not, and the fit that estimates it is refused naming it, while the plain
    model is plausible and finds the tool."""
    rng = np.random.default_rng(3)
    robot = jaxcal.preset("panda")
    dh = (
        np.asarray(robot.dh)
        + np.c_[rng.normal(0, 2e-3, 7), rng.normal(0, 0.5, 7), rng.normal(0, 0.5, 7), rng.normal(0, 2e-3, 7)]
    )
    B, X = np.eye(4), np.eye(4)
    B[:3, :3] = Rotation.from_euler("xyz", [-0.1, 0.61, -0.02], degrees=True).as_matrix()
    B[:3, 3] = [-656.0, 589.0, 7.2]
    X[:3, :3] = Rotation.from_euler("xyz", [0.5, -0.9, 88.2], degrees=True).as_matrix()
    X[:3, 3] = [91.2, -11.6, 142.7]
    q = _one_distance_poses(robot, dh, B, X, 30, 400.0, rng)
    T = dh_fk(dh, q, convention=robot.convention, base=B, tool=X)
    assert np.ptp(-np.einsum("ki,ki->k", T[:, :3, 2], T[:, :3, 3])) < 1e-6
    T[:, :3, 3] += rng.normal(0, 0.05, (len(q), 3))
    T[:, :3, :3] = Rotation.from_rotvec(rng.normal(0, 2e-4, (len(q), 3))).as_matrix() @ T[:, :3, :3]
    meas = jaxcal.Measurements(q=q, measured=T)

    kw = dict(params="all", folds=3, nested_max_poses=0, compliance="no")  # the refusal is the point
    plain = jaxcal.calibrate_data(robot, meas, **kw)
    assert plain.report["plausible"], plain.report["implausible"]
    assert np.linalg.norm(np.asarray(plain.robot.tool)[:3, 3] - X[:3, 3]) < 2.0

    depth = jaxcal.calibrate_data(robot, meas, camera="depth", **kw)
    assert not depth.report["plausible"]
    assert "do not determine" in depth.report["implausible"]
    assert "camera_depth_scale" in depth.report["implausible"]
    assert depth.report["camera_parameters"]["camera_depth_scale"]["std_error"] > 0.1


def test_a_prismatic_stroke_counts_as_far_as_the_data_move_it(tmp_path):
    """A robot file without limits gives a prismatic joint +-1000 mm; judged by that stroke, a
    120 mm error of a 700 mm SCARA would pass the 5 % length limit. The thresholds take the
    stroke the data cover: 0.05 x (lengths + tool + span)."""
    rows = [(400.0, 350.0, 0.0, "R"), (0.0, 300.0, 180.0, "R"), (50.0, 0.0, 0.0, "P"), (0.0, 0.0, 0.0, "R")]
    text = 'name = "scara"\nconvention = "sdh"\nangle_unit = "deg"\n' + "".join(
        f'[[joints]]\ntheta = 0.0\nd = {d}\na = {a}\nalpha = {al}\ntype = "{t}"\n' for d, a, al, t in rows
    )
    (tmp_path / "scara.toml").write_text(text + "[tool]\nxyz = [0.0, 0.0, 80.0]\nrpy = [0.0, 0.0, 0.0]\n")
    robot = jaxcal.load_robot(tmp_path / "scara.toml")
    q = np.random.default_rng(1).uniform([-2, -2, 20.0, -3], [2, 2, 180.0, 3], (30, 4))
    span = q[:, 2].max() - q[:, 2].min()
    opts = jaxcal.Options()
    assert Thresholds.of(robot, opts).length_mm > 150.0
    want = 0.05 * (400 + 350 + 300 + 50 + 80 + span)
    assert abs(Thresholds.of(robot, opts, q).length_mm - want) < 1e-9


def test_mirror_images_that_fit_alike_are_named_together():
    """With positions alone the swaps and mirrors are reflections a turn apart, which the
    measurement frame takes: tied residuals are named together, not the first by rounding; a
    correction that fits clearly better is named alone."""
    from jaxcal.calibration._plausibility import explain

    before = (500.0, None)
    tied = [("swapped y, z", 2.0731, None), ("swapped x, y", 2.0730, None), ("mirrored z", 2.0731, None)]
    msg = explain(["x"], before, tied + [("joints reversed", 80.0, None)], LIMITS)
    assert "a position axis swapped or mirrored (swapped x, y; swapped y, z; mirrored z:" in msg
    assert "cannot be told" in msg
    alone = explain(["x"], before, [("swapped x, y", 0.05, None), ("mirrored z", 2.07, None)], LIMITS)
    assert "Likely cause: swapped x, y (" in alone


def test_data_that_fit_as_given_are_not_blamed_on_an_input_mistake():
    """Forty copies of one pose: implausible (one posture determines nothing), and the data fit
    as given, so no input mistake is named, however much a 'correction' shaves off a residual
    already at the rounding level."""
    robot = jaxcal.preset("ur5")
    sim = jaxcal.simulate(robot, n_robots=1, n_poses=40, seed=3, sigma_pos=0.01, sigma_rot=1e-5, base=True, tool=True)
    q, m = np.repeat(sim.q[0, :1], 40, 0), np.repeat(sim.measured[0, :1], 40, 0)
    res = jaxcal.calibrate(robot, q, m)
    assert not res.plausible and "only 1 of the 40 data rows have distinct joint values" in res.implausible
    assert "Likely cause" not in res.implausible and "no input mistake" in res.implausible, res.implausible


def test_a_prismatic_column_in_another_unit_than_the_positions_is_named():
    """The bundled TIAGo file read with positions right but its torso column in metres taken for
    millimetres (one length option for both): the torso barely moves, the fit is refused, and the
    likely cause names the prismatic column, the correction bringing the residual to the data's."""
    from jaxcal.measurements import tiago_paths

    urdf, csv = tiago_paths()
    robot = jaxcal.load_robot(urdf)
    m = jaxcal.read_measurements(csv, robot)
    q = np.array(m.q, copy=True)
    q[:, 0] /= 1000.0
    # the options of test_outliers' TIAGo fits (their compiled programs): the refusal is the point
    kw = dict(nested_max_poses=0, params="all", ridge_mm=3.0, compliance="no")
    rep = jaxcal.calibrate_data(robot, jaxcal.Measurements(q=q, measured=m.measured), **kw).report
    assert not rep["plausible"]
    assert "Likely cause: prismatic joints in metres read as millimetres" in rep["implausible"], rep["implausible"]


def test_a_dh_table_in_the_other_convention_is_named():
    """The UR5's table measured as a modified-DH arm (NumPy FK, tests.helpers) and read as standard
    DH, and the reverse: the refusal names the convention, with the frames-only residual the
    table gives in the other one (the same data's, at the noise)."""
    ur5 = jaxcal.preset("ur5")
    rng = np.random.default_rng(8)
    lim = np.asarray(ur5.q_limits)
    q = lim[:, 0] + rng.uniform(size=(40, 6)) * (lim[:, 1] - lim[:, 0])
    for truth, read in (("mdh", "sdh"), ("sdh", "mdh")):
        T = dh_fk(np.asarray(ur5.dh), q, convention=truth)
        points = T[:, :3, 3] + rng.normal(0, 0.02, (40, 3))
        res = jaxcal.calibrate(ur5.replace(convention=read), q, points)
        want = {"sdh": "modified DH, read as standard DH", "mdh": "standard DH, read as modified DH"}[read]
        assert not res.plausible and f"Likely cause: the robot file's DH table is {want}" in res.implausible, (
            res.implausible
        )
        assert f'(convention = "{truth}")' in res.implausible
        after = float(res.implausible.split(" to ")[-1].split(" mm")[0])
        assert after < 0.1  # the noise's 0.035 mm per point, with frames only


def test_a_measurement_frame_held_where_the_data_are_not_is_named():
    """Data measured by a tracker set up anew (another frame), calibrated with the base held at the
    robot file's (--no-estimate-base): refused, and the cause named (it was "none of the likely
    input mistakes explains it"). Positions from a NumPy FK in a turned, shifted frame."""
    ur5 = jaxcal.preset("ur5")
    rng = np.random.default_rng(3)
    lim = np.asarray(ur5.q_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], (30, 6))
    frame = np.eye(4)
    frame[:3, :3] = Rotation.from_euler("z", 0.7).as_matrix()
    frame[:3, 3] = [1500.0, -800.0, 200.0]
    points = (frame @ dh_fk(ur5.dh, q))[:, :3, 3] + rng.normal(0, 0.02, (30, 3))
    with pytest.warns(jaxcal.CalibrationWarning):
        res = jaxcal.calibrate(ur5, q, points, estimate_base=False)
    assert not res.plausible
    assert "Likely cause: the measurement frame held at the robot file's base" in res.implausible
