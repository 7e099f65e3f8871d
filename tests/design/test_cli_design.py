"""``jaxcal design`` writes a pose file that ``jaxcal montecarlo --poses-file`` calibrates on; the
simulated calibration lands near the design's predicted validation RMS."""

import json

import numpy as np
import pytest
from helpers import run_cli

import jaxcal


def test_design_then_montecarlo_on_its_poses(monkeypatch, capsys, tmp_path):
    # a long folder name with brackets: paths said whole, not wrapped or read as markup
    runs = tmp_path / ("run[1]-" + "x" * 80)
    out, js, mc = runs / "poses.csv", runs / "design.json", tmp_path / "mc.json"
    code, stdout, err = run_cli(
        monkeypatch, capsys, "design", "paper-6r", "--poses", "8", "--out", out, "--starts", "2",
        "--no-estimate-base", "--no-estimate-tool", "--random-sets", "50", "--json", js,
    )  # fmt: skip
    assert code in (0, None), err
    assert "random median" in stdout
    d = json.loads(js.read_text())
    assert out.read_text().startswith("q1,q2,q3,q4,q5,q6\n") and d["feasible"]
    # the pose file's units said where it is written and in the summary; no point for full poses
    assert f"wrote {out} (joint values in rad, the robot file's units)\n" in stdout and f"wrote {js}\n" in stdout
    assert d["units"]["pose_file"] == "joint values in rad" and d["points_mm"] is None
    code, stdout, err = run_cli(
        monkeypatch, capsys, "montecarlo", "paper-6r", "--poses-file", out, "--robots", "64", "--repeats", "0",
        "--json", mc,
    )  # fmt: skip
    assert code in (0, None), err
    m = json.loads(mc.read_text())
    assert m["n_poses"] == 8
    predicted = d["values"]["validation_rms_mm"]
    # 64 robots x 50 validation poses: the empirical RMS within ~15 % of the bound it attains
    assert 0.8 * predicted < m["validation_pos_rms_mm"] < 1.3 * predicted
    # the elimination calibrates on its own pair design: given poses are refused, not ignored
    code, _, err = run_cli(
        monkeypatch, capsys, "montecarlo", "paper-6r", "--poses-file", out, "--method", "elimination", "--robots", "8"
    )
    assert code == 2 and "--method" in err and "pair design" in err
    # a box that half of the given poses' tool points (NumPy forward kinematics) lie beyond: the
    # study says so instead of "in the box"
    from helpers import dh_fk

    import jaxcal

    r = jaxcal.preset("paper-6r")
    p = dh_fk(r.dh, jaxcal.design.read_poses(out, r), convention=r.convention, base=r.base, tool=r.tool)[:, :3, 3]
    lo, hi = p.min(0) - 50.0, p.max(0) + 50.0
    hi[0] = np.median(p[:, 0])
    box = ",".join(f"{v:.3f}" for v in np.r_[lo, hi])
    code, stdout, err = run_cli(
        monkeypatch, capsys, "montecarlo", "paper-6r", "--poses-file", out, "--robots", "8", "--repeats", "0",
        "--region", box, "--json", mc,
    )  # fmt: skip
    assert code in (0, None), err
    text = " ".join(stdout.split())
    assert "given, NOT all in" in text and "warning: some of the given calibration poses are outside" in text
    assert json.loads(mc.read_text())["conditions"]["given_poses_meet_conditions"] is False


def test_design_bad_region_names_the_flag(monkeypatch, capsys, tmp_path):
    code, _, err = run_cli(
        monkeypatch, capsys, "design", "paper-6r", "--poses", "8", "--out", tmp_path / "p.csv", "--region", "1,2,3"
    )
    assert code == 2 and "--region" in err and not (tmp_path / "p.csv").exists()


def test_design_for_a_point_with_full_poses_asked_is_refused(monkeypatch, capsys, tmp_path):
    """--point designs for positions alone; --full-pose beside it was ignored without a word."""
    args = ("design", "paper-6r", "--poses", "8", "--out", tmp_path / "p.csv", "--point", "0,0,1", "--full-pose")
    code, _, err = run_cli(monkeypatch, capsys, *args)
    assert code == 2 and "drop --full-pose" in err and not (tmp_path / "p.csv").exists()


@pytest.mark.parametrize(
    "args,said", [(("--poses", "4"), "--poses: 4 poses"), (("--poses", "8", "--noise-mm", "0"), "--noise-mm must be")]
)
def test_errors_name_the_design_commands_own_flags(monkeypatch, capsys, tmp_path, args, said):
    """The library's n_poses and sigma_pos_mm are said as the flags design has (--poses, --noise-mm)."""
    code, _, err = run_cli(monkeypatch, capsys, "design", "paper-6r", *args, "--out", tmp_path / "p.csv")
    assert code == 2 and said in err and "--n-poses" not in err and "--sigma-pos-mm" not in err


def _pose_file(path, q):
    """A pose file written with NumPy (header q1..qN, rad)."""
    path.write_text(
        ",".join(f"q{i + 1}" for i in range(q.shape[1]))
        + "\n"
        + "\n".join(",".join(repr(float(v)) for v in r) for r in q)
    )
    return path


def test_validation_file_sets_the_criterion_poses(monkeypatch, capsys, tmp_path):
    """--validation: the design's validation RMS is the criterion at the file's poses (the API's
    evaluate with q_val, itself checked against the CRLB in test_design), not at random ones."""
    import numpy as np

    import jaxcal
    from jaxcal import design

    robot = jaxcal.preset("paper-6r")
    lim = np.asarray(robot.q_limits)
    rng = np.random.default_rng(11)
    pool = _pose_file(tmp_path / "pool.csv", lim[:, 0] + rng.uniform(size=(40, 6)) * (lim[:, 1] - lim[:, 0]))
    q_val = rng.uniform(-0.3, 0.3, size=(6, 6))  # a small working region, unlike the random default
    val = _pose_file(tmp_path / "val.csv", q_val)
    out, js = tmp_path / "poses.csv", tmp_path / "design.json"
    code, stdout, err = run_cli(
        monkeypatch, capsys, "design", "paper-6r", "--poses", "8", "--out", out, "--pool", pool,
        "--validation", val, "--no-estimate-base", "--no-estimate-tool", "--random-sets", "10", "--json", js,
    )  # fmt: skip
    assert code in (0, None), err
    d = json.loads(js.read_text())
    assert d["validation_poses"] == {"file": str(val), "count": 6}
    chosen = design.read_poses(out, robot)
    frames = dict(estimate_base=False, estimate_tool=False)
    at_file = design.evaluate(design.design_problem(robot, q_val=q_val, **frames), chosen)["validation_rms_mm"]
    at_random = design.evaluate(design.design_problem(robot, **frames), chosen)["validation_rms_mm"]
    np.testing.assert_allclose(d["values"]["validation_rms_mm"], at_file, rtol=1e-9)
    assert abs(at_file - at_random) > 0.01 * at_random


@pytest.mark.parametrize("flag", ["--validation", "--pool"])
def test_bad_pose_file_names_its_flag(monkeypatch, capsys, tmp_path, flag):
    bad = tmp_path / "bad.csv"
    bad.write_text("q1,q2,q3,q4,q5,q6\n0,0,0,zero,0,0\n")
    out = tmp_path / "p.csv"
    code, _, err = run_cli(monkeypatch, capsys, "design", "paper-6r", "--poses", "8", "--out", out, flag, bad)
    err = " ".join(err.split())
    assert code == 2 and f"{flag}: " in err and "column 'q4': not a number" in err and "Traceback" not in err, err
    assert not out.exists()


def test_design_bad_view_names_the_flag(monkeypatch, capsys, tmp_path):
    code, _, err = run_cli(
        monkeypatch, capsys, "design", "paper-6r", "--poses", "8", "--out", tmp_path / "p.csv", "--view", "0,0,0,1,0,0"
    )
    err = " ".join(err.split())
    assert code == 2 and "--view must be 7 or 9 comma-separated numbers" in err and not (tmp_path / "p.csv").exists()


def test_montecarlo_judges_a_design_in_its_conditions(monkeypatch, capsys, tmp_path):
    """montecarlo --view --validation FILE draws its random poses in the cone and inspects at the
    file's poses, and its JSON says so; a design made for the same conditions runs there with
    --poses-file, checked against them."""
    import numpy as np

    import jaxcal
    from jaxcal import design

    robot = jaxcal.preset("paper-6r")
    cone = ([2500.0, 0.0, 300.0], [-1.0, 0.0, 0.0], np.radians(12.0), 1500.0, 3500.0)
    view = "2500,0,300,-1,0,0,12,1500,3500"
    val, js, poses = tmp_path / "val.csv", tmp_path / "mc.json", tmp_path / "poses.csv"
    design.write_poses(val, design.random_poses(robot, 12, view=cone, seed=3), robot)
    common = ("--robots", "64", "--repeats", "0", "--view", view, "--validation", val, "--json", js)
    code, stdout, err = run_cli(monkeypatch, capsys, "montecarlo", "paper-6r", "--poses", "8", *common)
    assert code in (0, None), err
    m = json.loads(js.read_text())
    assert m["n_poses"] == 8 and m["n_val"] == 12 and m["validation_pos_rms_mm"] > 0
    c = m["conditions"]
    assert c["calibration_poses"] == "random, constrained" and c["validation_poses_file"] == str(val)
    assert c["view"]["origin_mm"] == cone[0] and c["view"]["near_mm"] == 1500.0 and 0.1 < c["acceptance"] < 0.6
    code, _, err = run_cli(
        monkeypatch, capsys, "design", "paper-6r", "--poses", "8", "--out", poses, "--starts", "2",
        "--no-estimate-base", "--no-estimate-tool", "--random-sets", "50", "--view", view, "--validation", val,
    )  # fmt: skip
    assert code in (0, None), err
    code, _, err = run_cli(monkeypatch, capsys, "montecarlo", "paper-6r", "--poses-file", poses, *common)
    assert code in (0, None), err
    c = json.loads(js.read_text())["conditions"]
    assert c["calibration_poses"] == "given" and c["given_poses_meet_conditions"]
    assert c["calibration_poses_file"] == str(poses)
    # --point: the study measures that point (as design --point), and judges the poses there
    far = ("--point", "0,0,3000", "--position-only")
    code, _, err = run_cli(monkeypatch, capsys, "montecarlo", "paper-6r", "--poses-file", poses, *common, *far)
    assert code in (0, None), err
    c = json.loads(js.read_text())["conditions"]
    assert c["given_poses_meet_conditions"] is False and c["point_mm"] == [0.0, 0.0, 3000.0]
    code, _, err = run_cli(monkeypatch, capsys, "montecarlo", "paper-6r", "--point", "0,0,30", "--robots", "3")
    assert code == 2 and "--position-only" in err
    # the study measures one point: a second is refused, not dropped
    two = ("--point", "0,0,30", "--point", "0,30,0", "--position-only", "--robots", "3")
    code, _, err = run_cli(monkeypatch, capsys, "montecarlo", "paper-6r", *two)
    assert code == 2 and "--point given 2 times" in " ".join(err.split())


def test_pose_file_beyond_the_limits_and_a_spread_no_pose_set_meets(monkeypatch, capsys, tmp_path):
    """A pool value beyond the joint limits the robot file gives is refused by its data row, line
    and column; a joint given none (the UR5 preset's) may turn beyond the range designs are drawn
    in (+-pi), as a real UR5's does, and its value is read as it is; a minimum spread the poses in
    the box cannot keep names --min-spread, not a pool never given."""
    from jaxcal.design import read_poses

    pool = tmp_path / "pool.csv"
    q = np.random.default_rng(7).uniform(-2.9, 2.9, (40, 6))
    q[5, 2] = 3.3  # data row 6, line 7
    pool.write_text("q1,q2,q3,q4,q5,q6\n" + "".join(",".join(repr(float(v)) for v in r) + "\n" for r in q))
    out = tmp_path / "p.csv"
    code, _, err = run_cli(monkeypatch, capsys, "design", "paper-6r", "--poses", "8", "--out", out, "--pool", pool)
    err = " ".join(err.split())
    assert code == 2 and "row 6 (line 7), column 'q3': 3.3 is outside the joint limits" in err, err
    assert not out.exists()
    assert read_poses(pool, jaxcal.preset("ur5"))[5, 2] == 3.3
    degrees = tmp_path / "deg.csv"
    degrees.write_text(
        "q1,q2,q3,q4,q5,q6\n" + "".join(",".join(repr(float(v)) for v in r) + "\n" for r in np.degrees(q))
    )
    with pytest.raises(jaxcal.DataError, match="look like degrees"):
        read_poses(degrees, jaxcal.preset("ur5"))
    code, _, err = run_cli(
        monkeypatch, capsys, "design", "ur5", "--poses", "8", "--out", out, "--region", "-900,-900,-200,900,900,900",
        "--min-spread", "9", "--random-sets", "5", "--starts", "1",
    )  # fmt: skip
    err = " ".join(err.split())
    assert code == 2 and "--min-spread: only" in err and "fewer than the 8 asked for" in err, err
    assert not out.exists()


def test_a_box_too_small_for_the_default_start_pool_still_gives_the_poses(monkeypatch, capsys, tmp_path):
    """A box that about 1 in 1500 configurations reach: a start pool of 1000 such poses (or 200
    validation poses) would need more draws than allowed, the 12 poses asked for do not; the
    design is made, within it."""
    out = tmp_path / "p.csv"
    code, stdout, err = run_cli(
        monkeypatch, capsys, "design", "ur5", "--poses", "12", "--out", out, "--region", "285,285,185,435,435,335",
        "--random-sets", "5", "--starts", "1", "--seed", "1",
    )  # fmt: skip
    assert code in (0, None), err
    assert "validation poses: 200 random within the joint limits, not only in the region" in " ".join(stdout.split())
    import jaxcal

    r = jaxcal.preset("ur5")
    p = np.asarray(jaxcal.fk(r, jaxcal.design.read_poses(out, r)))[:, :3, 3]
    assert len(p) == 12 and np.all(
        (p >= [285 - 1e-6, 285 - 1e-6, 185 - 1e-6]) & (p <= [435 + 1e-6, 435 + 1e-6, 335 + 1e-6])
    )


def test_a_position_only_design_says_which_point_it_is_for(monkeypatch, capsys, tmp_path):
    js = tmp_path / "d.json"
    common = ("design", "paper-6r", "--poses", "10", "--position-only", "--starts", "1", "--random-sets", "10")
    code, stdout, err = run_cli(monkeypatch, capsys, *common, "--out", tmp_path / "p.csv", "--json", js)
    assert code in (0, None), err
    assert "measured point: not given (--point)" in " ".join(stdout.split())
    d = json.loads(js.read_text())
    assert np.linalg.norm(d["points_mm"]) == pytest.approx(1.0) and d["units"]["q"].startswith("rad")
    code, stdout, err = run_cli(
        monkeypatch, capsys, *common, "--point", "0,40,30", "--out", tmp_path / "q.csv", "--json", js
    )  # fmt: skip
    assert code in (0, None), err
    assert "not given" not in stdout and json.loads(js.read_text())["points_mm"] == [[0.0, 40.0, 30.0]]
    # a rotation noise weighs nothing in a design for positions: refused by its flag, nothing written
    code, _, err = run_cli(monkeypatch, capsys, *common, "--noise-rad", "1e-4", "--out", tmp_path / "r.csv")
    assert code == 2 and "--noise-rad" in err and "positions" in err, err
    assert not (tmp_path / "r.csv").exists()


def test_a_pool_that_cannot_identify_the_parameters_is_refused(monkeypatch, capsys, tmp_path):
    """Two joints held still over the whole pool: no set of its poses identifies the base
    parameters, so the design is refused, naming those joints, and nothing is written (it used to
    be written, its criteria infinite, called feasible)."""
    import jaxcal

    lim = np.asarray(jaxcal.preset("ur5").q_limits)
    pool = np.random.default_rng(0).uniform(lim[:, 0], lim[:, 1], size=(200, 6))
    pool[:, 1], pool[:, 2] = -1.0, 0.5
    src, out = tmp_path / "pool.csv", tmp_path / "poses.csv"
    np.savetxt(src, pool, delimiter=",", header="q1,q2,q3,q4,q5,q6", comments="")
    code, _, err = run_cli(monkeypatch, capsys, "design", "ur5", "--poses", "20", "--pool", src, "--out", out)
    assert code == 2 and "--pool" in err and "joints 2, 3 never move" in err and "identify" in err, err
    assert not out.exists()
    code, _, err = run_cli(
        monkeypatch, capsys, "design", "ur5", "--poses", "20", "--point", "nan,0,0", "--out", out
    )  # fmt: skip
    assert code == 2 and "--point " in err and "finite" in err, err
    code, _, err = run_cli(
        monkeypatch, capsys, "design", "ur5", "--poses", "20", "--pool", tmp_path / "no.csv", "--out", out
    )
    assert code == 2 and "pose file not found" in err, err


def test_params_from_a_position_only_report_designs_for_its_points(monkeypatch, capsys, tmp_path):
    """A --params-from report of a calibration on positions of two markers: the design measures
    two points by position, as that calibration did (it designed for full poses without a word),
    and says so; --full-pose designs for poses."""
    rep = tmp_path / "rep.json"
    names = list(jaxcal.preset("paper-6r").param_names())
    rep.write_text(json.dumps({"estimated_dh": names, "position_only": True, "points": 2, "estimate_tool": True}))
    common = ("design", "paper-6r", "--poses", "8", "--params-from", rep, "--starts", "1", "--random-sets", "5")
    code, out, err = run_cli(monkeypatch, capsys, *common, "--out", tmp_path / "p.csv", "--json", tmp_path / "p.json")
    assert code in (0, None), err
    assert "measured: positions of 2 point(s) on the tool, as in the --params-from calibration" in " ".join(out.split())
    assert len(json.loads((tmp_path / "p.json").read_text())["points_mm"]) == 2
    code, out, err = run_cli(
        monkeypatch, capsys, *common, "--full-pose", "--out", tmp_path / "f.csv", "--json", tmp_path / "f.json"
    )
    assert code in (0, None), err
    assert "positions of" not in out and not json.loads((tmp_path / "f.json").read_text()).get("points_mm")
