"""UR kinematics files (`jaxcal.save_ur_kinematics`): the forward kinematics computed from the
written YAML alone (PyYAML and NumPy, `helpers.ur_yaml_fk`) reproduces the robot's; the UR
presets give UR's published nominal files; the file reads back; other robots are refused."""

import numpy as np
import pytest
import yaml
from helpers import (
    UR_DH,
    dh_fk,
    pairwise_distances,
    random_dh,
    random_transform,
    ur5_factory_doc,
    ur_nominal_origins,
    ur_yaml_fk,
)

import jaxcal
from jaxcal import RobotFileError, preset
from jaxcal.export import save_ur_kinematics, ur_kinematics


@pytest.mark.parametrize("name", list(UR_DH))
def test_presets_write_urs_nominal_file(tmp_path, name):
    """UR's nominal files, entry by entry: shoulder z = d1, upper_arm roll = alpha1, forearm
    x = a2, wrist_1 x = a3 and z = d4, wrist_2 y = -d5 and roll = pi/2, wrist_3 y = d6 and a
    turn by alpha5 = -pi/2 about x (UR writes it as rpy (pi/2, pi, pi))."""
    save_ur_kinematics(preset(name), tmp_path / "k.yaml")
    kin = yaml.safe_load((tmp_path / "k.yaml").read_text())["kinematics"]
    expect = ur_nominal_origins(name)
    for key, vals in expect.items():
        got = [kin[key][k] for k in ("x", "y", "z", "roll", "pitch", "yaw")]
        np.testing.assert_allclose(got, vals, atol=1e-12, err_msg=key)
    assert list(kin) == [*expect, "hash"] and kin["hash"].startswith("calib_") and kin["hash"][6:].isdigit()
    # UR's own spelling of wrist_3 is the same frame
    e = dict(kin["wrist_3"], roll=np.pi / 2, pitch=np.pi, yaw=np.pi)
    ur = ur_yaml_fk({"kinematics": dict(kin, wrist_3=e)}, np.zeros((1, 6)))
    np.testing.assert_allclose(ur, ur_yaml_fk({"kinematics": kin}, np.zeros((1, 6))), atol=1e-12)


@pytest.mark.parametrize("convention", ["sdh", "mdh"])
def test_yaml_fk_reproduces_the_robot(tmp_path, rng, convention):
    """A generic six-joint arm (offsets, a6 and alpha6 non-zero, base and tool): the YAML's chain
    gives the flange (tool0) positions up to a rigid motion, to 1e-6 mm; with the base and tool
    that `save_ur_kinematics` returns, the robot's end poses themselves."""
    dh = random_dh(rng)
    B, X = random_transform(rng, 500.0), random_transform(rng, 80.0)
    robot = jaxcal.Robot(dh, convention=convention, base=B, tool=X)
    base, tool = save_ur_kinematics(robot, tmp_path / "k.yaml")
    doc = yaml.safe_load((tmp_path / "k.yaml").read_text())
    q = rng.uniform(-np.pi, np.pi, (200, 6))
    chain = ur_yaml_fk(doc, q)
    chain[:, :3, 3] *= 1000.0  # m -> mm
    ends = dh_fk(dh, q, convention=convention, base=B, tool=X)
    np.testing.assert_allclose(base @ chain @ tool, ends, atol=1e-9)
    flange = dh_fk(dh, q, convention=convention)  # jaxcal's flange: base and tool left out
    if convention == "sdh":  # UR's flange is DH frame 6 less its link's Tx(a6) Rx(alpha6)
        tail = np.eye(4)
        tail[0, 3] = dh[5, 2]
        c, s = np.cos(dh[5, 3]), np.sin(dh[5, 3])
        tail[1:3, 1:3] = [[c, -s], [s, c]]
        flange = flange @ np.linalg.inv(tail)
    worst = np.abs(pairwise_distances(chain[:, :3, 3]) - pairwise_distances(flange[:, :3, 3])).max()
    assert worst < 1e-6, worst


def test_reads_back(tmp_path, rng):
    """The file reads back (`load_robot`) as a modified-DH arm with the same kinematics from UR's
    base to tool0; UR's nominal values round-trip to the preset's table."""
    robot = jaxcal.Robot(random_dh(rng), convention="sdh", base=random_transform(rng), tool=random_transform(rng))
    base, tool = save_ur_kinematics(robot, tmp_path / "k.yaml")
    back = jaxcal.load_robot(tmp_path / "k.yaml")
    assert back.convention == "mdh" and back.units == ("m", "rad") and back.joint_names[0] == "shoulder_pan_joint"
    q = rng.uniform(-np.pi, np.pi, (50, 6))
    np.testing.assert_allclose(base @ np.asarray(jaxcal.fk(back, q)) @ tool, np.asarray(jaxcal.fk(robot, q)), atol=1e-9)
    save_ur_kinematics(preset("ur5"), tmp_path / "ur5.yaml")
    sdh = jaxcal.to_sdh(jaxcal.load_robot(tmp_path / "ur5.yaml"))
    np.testing.assert_allclose(np.asarray(sdh.dh), np.asarray(preset("ur5").dh), atol=1e-12)


def test_a_factory_style_file_reads_as_joint_frames(tmp_path, rng):
    """Origins off the DH form (UR's factory calibrations move them) read as joint frames whose
    kinematics is the file's."""
    save_ur_kinematics(preset("ur5"), tmp_path / "k.yaml")
    doc = yaml.safe_load((tmp_path / "k.yaml").read_text())
    for e in doc["kinematics"].values():
        if isinstance(e, dict):
            e["y"] += 1e-4
            e["pitch"] += 2e-3
    (tmp_path / "f.yaml").write_text(yaml.safe_dump(doc))
    back = jaxcal.load_robot(tmp_path / "f.yaml")
    assert back.convention == "joint"
    q = rng.uniform(-np.pi, np.pi, (20, 6))
    want = ur_yaml_fk(doc, q)
    want[:, :3, 3] *= 1000.0
    np.testing.assert_allclose(np.asarray(jaxcal.fk(back, q)), want, atol=1e-9)


def test_a_factory_calibration_calibrated_again_is_written_back(tmp_path, rng):
    """A factory-style file read as joint frames, its corrections and offsets changed as a
    calibration changes them: the YAML written with ``ur_chain`` gives, computed from the file
    alone, the robot's end poses with the returned base and tool, and reads back as the same
    arm. Without ``ur_chain`` (a URDF's chain often starts at base_link, pi from UR's base) it is
    refused, as are a joint turning about another axis than its origin's z and, with it, a chain
    whose first origin is turned by about pi (one from base_link)."""
    (tmp_path / "f.yaml").write_text(yaml.safe_dump(ur5_factory_doc(rng)))
    robot = jaxcal.load_robot(tmp_path / "f.yaml")
    assert robot.convention == "joint"
    dh = np.c_[rng.normal(0, 0.01, 6), rng.normal(0, 0.5, (6, 3)), rng.normal(0, 0.005, (6, 3))]
    cal = robot.replace(dh=dh, base=random_transform(rng, 500.0), tool=random_transform(rng, 80.0))
    with pytest.raises(RobotFileError, match="not known to be UR's base.*ur_chain=True"):
        save_ur_kinematics(cal, tmp_path / "out.yaml")
    assert not (tmp_path / "out.yaml").exists()
    base, tool = save_ur_kinematics(cal, tmp_path / "out.yaml", ur_chain=True)
    doc = yaml.safe_load((tmp_path / "out.yaml").read_text())
    q = rng.uniform(-np.pi, np.pi, (200, 6))
    chain = ur_yaml_fk(doc, q)
    chain[:, :3, 3] *= 1000.0  # m -> mm
    np.testing.assert_allclose(base @ chain @ tool, np.asarray(jaxcal.fk(cal, q)), atol=1e-9)
    back = jaxcal.load_robot(tmp_path / "out.yaml")
    np.testing.assert_allclose(base @ np.asarray(jaxcal.fk(back, q)) @ tool, np.asarray(jaxcal.fk(cal, q)), atol=1e-9)
    axes = np.array(cal.axes)
    axes[2] = [0.0, np.sin(0.01), np.cos(0.01)]
    tilted = cal.replace(axes=axes)
    with pytest.raises(RobotFileError, match="joint 3 turns about .* of its origin, not z"):
        save_ur_kinematics(tilted, tmp_path / "t.yaml", ur_chain=True)
    # the same chain from base_link, a turn of pi about z before UR's base: ROS would add its own
    origins = np.array(cal.origins)
    origins[0] = np.diag([-1.0, -1.0, 1.0, 1.0]) @ origins[0]
    with pytest.raises(RobotFileError, match="turned by -?3.1.. rad about z: the chain starts at base_link"):
        save_ur_kinematics(cal.replace(origins=origins), tmp_path / "t.yaml", ur_chain=True)
    assert not (tmp_path / "t.yaml").exists()


@pytest.mark.parametrize(
    "robot, why",
    [
        (preset("panda"), "it has 7 joints, not 6"),
        (preset("ur5").replace(joint_types=("R", "R", "P", "R", "R", "R")), "joint 3 is prismatic"),
        (jaxcal.to_joint(preset("ur5")), "joint frames whose first is not known to be UR's base"),
    ],
)
def test_other_robots_refused(tmp_path, robot, why):
    with pytest.raises(RobotFileError, match="needs a six-joint revolute arm as a DH table") as e:
        ur_kinematics(robot)
    assert why in str(e.value)
    with pytest.raises(RobotFileError):
        save_ur_kinematics(robot, tmp_path / "k.yaml")
    assert not (tmp_path / "k.yaml").exists()


@pytest.mark.parametrize(
    "text, msg",
    [
        ("joints: []\n", "read as UR's ROS 2 kinematics file; a DH table goes in a .toml robot file"),
        ("kinematics:\n  shoulder: 3\n", "kinematics.shoulder must be a mapping"),
        ("kinematics: [1, 2\n", "not valid YAML"),
    ],
)
def test_bad_files_refused(tmp_path, text, msg):
    (tmp_path / "bad.yaml").write_text(text)
    with pytest.raises(RobotFileError, match=msg):
        jaxcal.load_robot(tmp_path / "bad.yaml")


def test_missing_value_named(tmp_path):
    save_ur_kinematics(preset("ur5"), tmp_path / "k.yaml")
    doc = yaml.safe_load((tmp_path / "k.yaml").read_text())
    doc["kinematics"]["forearm"]["x"] = "abc"
    (tmp_path / "k.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(RobotFileError, match=r"kinematics.forearm.x must be a finite number, got 'abc'"):
        jaxcal.load_robot(tmp_path / "k.yaml")
    del doc["kinematics"]["wrist_2"]["roll"]
    doc["kinematics"]["forearm"]["x"] = 0.0
    (tmp_path / "k.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(RobotFileError, match=r"kinematics.wrist_2.roll is missing"):
        jaxcal.load_robot(tmp_path / "k.yaml")


def test_wrong_names_and_arguments_refused(tmp_path):
    """A UR file not named .yaml would be read back as TOML; a calibration result is not a robot."""
    r = preset("ur5")
    with pytest.raises(RobotFileError, match="a UR kinematics file is YAML and its name ends in .yaml"):
        save_ur_kinematics(r, tmp_path / "cal.toml")
    sim = jaxcal.simulate(r, n_poses=30, seed=1, sigma_pos=0.0)
    res = jaxcal.calibrate(r, sim.q[0], sim.measured[0, :, :3, 3])
    with pytest.raises(RobotFileError, match="takes a jaxcal.Robot .a result's .robot., not a CalibrationResult"):
        save_ur_kinematics(res, tmp_path / "cal.yaml")
    assert list(tmp_path.iterdir()) == []


def test_the_frames_it_does_not_hold_are_said_in_full_precision(tmp_path, rng):
    """The header comments give the base and tool to the last digit (1e-9 mm on frames of
    hundreds of mm), not to nine significant figures."""
    r = preset("ur5").replace(base=random_transform(rng, 700.0), tool=random_transform(rng, 150.0))
    base, tool = save_ur_kinematics(r, tmp_path / "cal.yaml")
    from scipy.spatial.transform import Rotation

    text = (tmp_path / "cal.yaml").read_text()
    for what, T in (("base", base), ("tool", tool)):
        line = next(x for x in text.splitlines() if x.startswith(f"#   {what} ("))
        xyz = np.array(line.split("xyz [")[1].split("]")[0].split(", "), float) * 1000.0
        rpy = np.array(line.split("rpy [")[1].split("]")[0].split(", "), float)
        np.testing.assert_allclose(xyz, np.asarray(T)[:3, 3], rtol=0, atol=1e-9)
        np.testing.assert_allclose(Rotation.from_euler("xyz", rpy).as_matrix(), np.asarray(T)[:3, :3], atol=1e-14)


def test_the_written_angles_follow_the_file_calibrated(tmp_path, rng):
    """A factory file with a yaw a whole turn off and wrist_3 written as UR writes it, (pi/2, pi,
    pi) rather than (-pi/2, 0, 0): with ``like`` the file the arm was read from, every written
    angle lies near the file's own (a diff shows what the calibration changed) and the
    kinematics are the same; without it, some angle jumps by about pi or a turn."""
    doc = ur5_factory_doc(rng)
    kin = doc["kinematics"]
    kin["wrist_1"]["yaw"] -= 2 * np.pi
    w = kin["wrist_3"]
    w.update(roll=w["roll"] + np.pi, pitch=np.pi - w["pitch"], yaw=w["yaw"] + np.pi)
    (tmp_path / "f.yaml").write_text(yaml.safe_dump(doc))
    robot = jaxcal.load_robot(tmp_path / "f.yaml")
    cal = robot.replace(dh=np.c_[rng.normal(0, 0.01, 6), rng.normal(0, 0.5, (6, 3)), rng.normal(0, 0.005, (6, 3))])
    q = rng.uniform(-np.pi, np.pi, (50, 6))
    angles = ("roll", "pitch", "yaw")
    jumps = []
    for like in (tmp_path / "f.yaml", None):
        base, tool = save_ur_kinematics(cal, tmp_path / "out.yaml", ur_chain=True, like=like)
        out = yaml.safe_load((tmp_path / "out.yaml").read_text())
        chain = ur_yaml_fk(out, q)
        chain[:, :3, 3] *= 1000.0
        np.testing.assert_allclose(base @ chain @ tool, np.asarray(jaxcal.fk(cal, q)), atol=1e-9)
        jumps.append(max(abs(out["kinematics"][k][a] - kin[k][a]) for k in kin if k != "hash" for a in angles))
    assert jumps[0] < 0.1 and jumps[1] > 3.0, jumps
