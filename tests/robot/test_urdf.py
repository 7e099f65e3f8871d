"""URDF in and out: the chain read by jaxcal against yourdfpy's own forward kinematics (its
scene graph, an independent implementation), written models reloaded to 1e-9 mm, and bad files
named."""

import re

import numpy as np
import pytest
import yourdfpy

from jaxcal import DataError, RobotFileError, fk, load_model, load_robot, save_model, to_joint
from jaxcal.lie import xyz_rpy_to_transform
from jaxcal.measurements import tiago_paths
from jaxcal.model import Model

URDF, _ = tiago_paths()


def _yourdfpy_fk(path, names, q, tip, base=None):
    """Tool poses (mm) from yourdfpy's scene graph; prismatic joint values in m."""
    u = yourdfpy.URDF.load(str(path), build_scene_graph=True, load_meshes=False)
    out = []
    for row in q:
        u.update_cfg(dict(zip(names, row)))
        T = np.array(u.get_transform(frame_to=tip, frame_from=base or u.base_link))
        T[:3, 3] *= 1000.0
        out.append(T)
    return np.stack(out)


def _random_q(robot, rng, k=6):
    lim = np.asarray(robot.q_limits)
    return lim[:, 0] + rng.uniform(size=(k, robot.n_joints)) * (lim[:, 1] - lim[:, 0])


def test_tiago_chain_matches_yourdfpy():
    rng = np.random.default_rng(25)
    r = load_robot(URDF)
    assert r.convention == "joint" and r.units == ("m", "rad")
    assert r.joint_names == ("torso_lift_joint",) + tuple(f"arm_{i}_joint" for i in range(1, 8))
    assert r.joint_types == ("P",) + ("R",) * 7
    np.testing.assert_allclose(np.asarray(r.q_limits)[0], [0.0, 350.0])  # metres in the file, mm inside
    q = _random_q(r, rng)
    q_file = q.copy()
    q_file[:, 0] /= 1000.0
    expect = _yourdfpy_fk(URDF, r.joint_names, q_file, "wrist_ft_tool_link")
    np.testing.assert_allclose(np.asarray(fk(r, q)), expect, atol=1e-9)


def test_sub_chain_by_links():
    rng = np.random.default_rng(1)
    r = load_robot(URDF, base_link="torso_lift_link", tip_link="arm_4_link")
    assert r.joint_names == ("arm_1_joint", "arm_2_joint", "arm_3_joint", "arm_4_joint")
    q = _random_q(r, rng)
    expect = _yourdfpy_fk(URDF, r.joint_names, q, "arm_4_link", base="torso_lift_link")
    np.testing.assert_allclose(np.asarray(fk(r, q)), expect, atol=1e-9)


def _calibrated(rng):
    r = load_robot(URDF)
    dh = rng.normal(size=(r.n_joints, 7)) * np.array([0.01, 1.0, 1.0, 1.0, 0.01, 0.01, 0.01])
    base = np.asarray(xyz_rpy_to_transform(np.array([120.0, -40.0, 30.0]), np.array([0.1, -0.2, 0.3])))
    tool = np.asarray(r.tool) @ np.asarray(xyz_rpy_to_transform(np.array([1.0, 2.0, 3.0]), np.array([0.01, 0.0, 0.02])))
    return r.replace(dh=dh, base=base, tool=tool), rng.normal(size=(4, 3)) * 60.0


@pytest.mark.parametrize("template", [True, False], ids=["into-the-nominal-file", "own-chain"])
def test_written_model_reloads_to_the_same_kinematics(tmp_path, template):
    rng = np.random.default_rng(7)
    cal, points = _calibrated(rng)
    path = tmp_path / "cal.urdf"
    save_model(Model(cal, points), path, template=URDF if template else None, comment={"data": "x.csv"})
    back = load_model(path)
    q = _random_q(cal, rng, 20)
    np.testing.assert_allclose(np.asarray(fk(back.robot, q)), np.asarray(fk(cal, q)), atol=1e-9)
    np.testing.assert_allclose(np.asarray(back.points), points, atol=1e-12)
    assert back.robot.joint_names == cal.joint_names
    # the file is a URDF any parser reads: yourdfpy's kinematics from the measurement frame to
    # the first point agree
    q_file = q.copy()
    q_file[:, 0] /= 1000.0
    T = _yourdfpy_fk(path, cal.joint_names, q_file, "jaxcal_point1", base="jaxcal_measurement_frame")
    expect = np.asarray(fk(cal, q))
    p1 = expect[:, :3, 3] + np.einsum("kij,j->ki", expect[:, :3, :3], points[0])
    np.testing.assert_allclose(T[:, :3, 3], p1, atol=1e-9)
    if template:  # the nominal file's other links are kept
        assert "torso_fixed_link" in path.read_text()


def test_the_written_file_records_its_chain(tmp_path):
    """A sub-chain whose base link is not the root (torso_lift_link): the measurement frame hangs
    under it and the root stays; the file reads back with no link options, in the measurement
    frame, and options must name the recorded chain."""
    rng = np.random.default_rng(11)
    cal, points = _calibrated(rng)
    sub = load_robot(URDF, base_link="torso_lift_link")
    cal = sub.replace(dh=np.asarray(cal.dh)[1:], base=cal.base, tool=cal.tool)
    path = tmp_path / "cal.urdf"
    save_model(Model(cal, points), path, template=URDF, base_link="torso_lift_link")
    back = load_model(path)
    q = _random_q(cal, rng, 10)
    np.testing.assert_allclose(np.asarray(fk(back.robot, q)), np.asarray(fk(cal, q)), atol=1e-9)
    assert back.robot.joint_names == cal.joint_names and back.n_points == 4
    T = _yourdfpy_fk(path, cal.joint_names, q, "jaxcal_point2", base="jaxcal_measurement_frame")
    expect = np.asarray(fk(cal, q))
    np.testing.assert_allclose(T[:, :3, 3], expect[:, :3, 3] + expect[:, :3, :3] @ points[1], atol=1e-9)
    u = yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False)
    parent = {j.child: j.parent for j in u.robot.joints}
    assert {lk.name for lk in u.robot.links} - set(parent) == {"base_footprint"}  # the root stays
    assert parent["jaxcal_measurement_frame"] == "torso_lift_link"
    assert parent["jaxcal_tool"] == "wrist_ft_tool_link" and parent["jaxcal_point1"] == "jaxcal_tool"
    same = load_model(path, base_link="torso_lift_link", tip_link="wrist_ft_tool_link")
    np.testing.assert_allclose(np.asarray(same.robot.tool), np.asarray(back.robot.tool), atol=0)
    with pytest.raises(RobotFileError, match=r"chain from 'torso_lift_link'; 'base_footprint' \(base_link\)"):
        load_model(path, base_link="base_footprint")
    with pytest.raises(RobotFileError, match=r"to 'wrist_ft_tool_link'; 'arm_7_link' \(tip_link\) does not match"):
        load_model(path, tip_link="arm_7_link")


RICH = """<?xml version="1.0"?>
<!-- Licence: kept with the file, © its authors -->
<robot name="rich">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="finger_a"/><link name="finger_b"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.3" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="10" velocity="1"/>
    <safety_controller soft_lower_limit="-1.9" soft_upper_limit="1.9" k_position="100" k_velocity="10"/>
    <calibration rising="0.1"/><dynamics damping="0.5"/>
  </joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.4 0 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 1 1"/>
    <limit lower="-2" upper="2" effort="10" velocity="1"/>
  </joint>
  <joint name="fa" type="prismatic"><parent link="l2"/><child link="finger_a"/>
    <axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/>
  </joint>
  <joint name="fb" type="prismatic"><parent link="l2"/><child link="finger_b"/>
    <axis xyz="0 -1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/><mimic joint="fa"/>
  </joint>
  <transmission name="t1"><type>transmission_interface/SimpleTransmission</type></transmission>
  <gazebo reference="l1"><material>Gazebo/Grey</material></gazebo>
  <ros2_control name="arm" type="system"><hardware><plugin>mock</plugin></hardware></ros2_control>
</robot>
"""


def test_the_written_file_keeps_everything_but_the_chain_origins(tmp_path):
    """Mimic joints, safety limits, transmissions, Gazebo and ros2_control blocks and the file's
    comments come through a calibration unchanged; only the chain joints' origins and axes (and
    jaxcal's own links) differ; written twice, the calibration's links and comment are not doubled."""
    from lxml import etree

    nominal = tmp_path / "rich.urdf"
    nominal.write_text(RICH, encoding="utf-8")
    r = load_robot(nominal, base_link="base", tip_link="l2")
    cal = r.replace(dh=np.full((2, 7), 1e-3), base=np.asarray(xyz_rpy_to_transform(np.ones(3), np.zeros(3))))
    first, second = tmp_path / "first.urdf", tmp_path / "second.urdf"
    chain = dict(base_link="base", tip_link="l2")
    save_model(Model(cal, np.ones((1, 3))), first, template=nominal, comment={"data": "a.csv"}, **chain)
    again = load_model(first)  # its origins carry the corrections: written again, the same arm
    save_model(again, second, template=first, comment={"data": "donnée/b.csv"})

    def elements(path):
        root = etree.parse(str(path), etree.XMLParser(remove_blank_text=True)).getroot()
        for el in root.iter("origin", "axis"):  # the chain's own, compared apart
            if el.getparent().get("name") in ("j1", "j2"):
                el.getparent().remove(el)
        return [etree.tostring(e) for e in root if not (e.get("name") or "").startswith("jaxcal_")]

    assert elements(second) == elements(nominal)
    text = second.read_text(encoding="utf-8")
    assert "Licence: kept with the file, © its authors" in text and "jaxcal: data: donnée/b.csv" in text
    assert text.count("jaxcal: data") == 1
    assert text.count('<link name="jaxcal_') == 3 and "<mimic" in text
    u = yourdfpy.URDF.load(str(second), build_scene_graph=True, load_meshes=False)
    assert u.actuated_joint_names == ["j1", "j2", "fa"]  # fb still follows fa
    back = load_robot(second)
    np.testing.assert_allclose(np.asarray(back.dh), 0.0, atol=1e-12)  # the corrections are in the origins
    q = np.array([[0.3, -0.4]])
    u.update_cfg({"j1": 0.3, "j2": -0.4, "fa": 0.0})
    T = np.array(u.get_transform(frame_to="l2", frame_from="base"))
    T[:3, 3] *= 1000.0
    np.testing.assert_allclose(T, _joint_chain_pose(cal, q[0]), atol=1e-9)


def _joint_chain_pose(robot, q):
    """base link -> tip link of a joint-frame robot from its origins, corrections and axes, in
    NumPy (URDF: origin, then the joint's motion)."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    for i in range(robot.n_joints):
        p = np.array(robot.dh[i])
        E = np.eye(4)
        E[:3, :3] = Rotation.from_rotvec(p[4:7]).as_matrix()
        E[:3, 3] = p[1:4]
        M = np.eye(4)
        M[:3, :3] = Rotation.from_rotvec(np.array(robot.axes[i]) * (q[i] + p[0])).as_matrix()
        T = T @ np.asarray(robot.origins)[i] @ E @ M
    return T


def test_a_calibrated_file_calibrated_again_and_the_earlier_layout(tmp_path):
    """A calibrated file as the nominal of a new calibration: its chain and added links are
    replaced, not doubled. A file of the earlier layout (the measurement frame as the root,
    above the base link) reads the same, against yourdfpy."""
    rng = np.random.default_rng(5)
    cal, points = _calibrated(rng)
    first = tmp_path / "first.urdf"
    save_model(Model(cal, points), first, template=URDF)
    again = load_model(first).robot
    again = again.replace(dh=rng.normal(size=(8, 7)) * 1e-3, base=np.asarray(again.base) @ np.diag([1, -1, -1, 1.0]))
    second = tmp_path / "second.urdf"
    save_model(Model(again, points[:2]), second, template=first)
    back = load_model(second)
    q = _random_q(cal, rng, 10)
    np.testing.assert_allclose(np.asarray(fk(back.robot, q)), np.asarray(fk(again, q)), atol=1e-9)
    assert back.n_points == 2 and second.read_text().count('link name="jaxcal_') == 4

    # the earlier layout, by hand: the measurement frame the root, base_footprint below it
    u = yourdfpy.URDF.load(str(first), build_scene_graph=False, load_meshes=False)
    (j,) = [j for j in u.robot.joints if j.child == "jaxcal_measurement_frame"]
    j.parent, j.child = "jaxcal_measurement_frame", "base_footprint"
    T = np.linalg.inv(np.asarray(j.origin))
    j.origin = T
    old = tmp_path / "old.urdf"
    old.write_bytes(yourdfpy.URDF(robot=u.robot, build_scene_graph=False, load_meshes=False).write_xml_string())
    back = load_model(old)
    q_file = q.copy()
    q_file[:, 0] /= 1000.0
    expect = _yourdfpy_fk(old, cal.joint_names, q_file, "jaxcal_point3", base="jaxcal_measurement_frame")
    got = np.asarray(fk(back.robot, q))
    np.testing.assert_allclose(got[:, :3, 3] + got[:, :3, :3] @ np.asarray(back.points)[2], expect[:, :3, 3], atol=1e-9)


def test_dh_robot_in_joint_frames_has_the_same_kinematics():
    from helpers import dh_fk

    from jaxcal import preset

    rng = np.random.default_rng(3)
    for name in ("ur5", "panda", "puma560"):
        r = preset(name)
        q = _random_q(r, rng)
        np.testing.assert_allclose(np.asarray(fk(to_joint(r), q)), np.asarray(fk(r, q)), atol=1e-9)
    # and against the independent NumPy FK, with a prismatic joint
    r = preset("ur5").replace(joint_types=("R", "P", "R", "R", "R", "R"))
    q = _random_q(r, rng)
    np.testing.assert_allclose(
        np.asarray(fk(to_joint(r), q)), dh_fk(np.asarray(r.dh), q, joint_types=r.joint_types), atol=1e-9
    )


BAD = {
    "floating joint": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j" type="floating"><parent link="a"/><child link="b"/></joint></robot>',
        "joint 'j' is floating",
    ),
    "two tips": (
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/>'
        '<joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        '<joint name="j2" type="revolute"><parent link="a"/><child link="c"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>',
        "2 tip links below 'a' (b, c); choose one (tip_link)",
    ),
    "only fixed joints": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint></robot>',
        "no movable joint between 'a' and 'b'",
    ),
    "not xml": ("<robot name=", "not a readable URDF"),
    "two parents": (
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/>'
        '<joint name="j1" type="fixed"><parent link="a"/><child link="c"/></joint>'
        '<joint name="j2" type="fixed"><parent link="b"/><child link="c"/></joint></robot>',
        "link 'c' is the child of two joints ('j1', 'j2'); a URDF is a tree",
    ),
    "no axis direction": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0 0 0"/></joint></robot>',
        "joint 'j' has axis [0.0, 0.0, 0.0]; a movable joint needs a direction",
    ),
    "limits reversed": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>'
        '<limit lower="1" upper="-1" effort="1" velocity="1"/></joint></robot>',
        "joint 'j' has limits lower 1.0 > upper -1.0",
    ),
    "limits equal": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>'
        '<limit lower="0" upper="0" effort="1" velocity="1"/></joint></robot>',
        "joint 'j' has limits lower 0.0 = upper: it cannot move",
    ),
    "a joint name used twice": (
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/>'
        '<joint name="j" type="continuous"><parent link="a"/><child link="b"/></joint>'
        '<joint name="j" type="continuous"><parent link="b"/><child link="c"/></joint></robot>',
        "joint name(s) 'j' used twice; URDF names are unique",
    ),
    "prismatic axis not unit": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="lift" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="0 0 2"/>'
        '<limit lower="0" upper="0.3" effort="1" velocity="1"/></joint></robot>',
        "prismatic joint 'lift' has axis [0.0, 0.0, 2.0] of length 2; URDF axes are unit vectors",
    ),
    "robot without a name": ("<robot></robot>", "not a readable URDF: a required attribute 'name' is missing"),
    "XML cut off in an attribute": (
        '<robot name="r"><link name="a"/><link name="b"/><joint name="j" type="revolute"><parent link="a',
        "not a readable URDF: the XML is broken",
    ),
    # yourdfpy recovers from this one by dropping the rest of the file: the tip would be "missing"
    "a link left open before the rest of the chain": (
        '<robot name="r"><link name="a"><link name="b"/><link name="c"/>'
        '<joint name="j" type="continuous"><parent link="a"/><child link="b"/></joint>'
        '<joint name="k" type="continuous"><parent link="b"/><child link="c"/></joint></robot>',
        "not a readable URDF: the XML is broken",
    ),
    "a bare ampersand": ('<robot name="r & co"><link name="a"/></robot>', "not a readable URDF: the XML is broken"),
    "axis of two numbers": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j2" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>',
        "line 1: joint 'j2', <axis xyz='0 1'>: 2 number(s), not 3",
    ),
    "origin of two numbers": (
        '<robot name="r"><link name="a"/><link name="b"/>\n'
        '<joint name="j2" type="continuous"><parent link="a"/><child link="b"/><origin xyz="0.3 0"/></joint></robot>',
        "line 2: joint 'j2', <origin xyz='0.3 0'>: 2 number(s), not 3",
    ),
    "a decimal comma": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j2" type="continuous"><parent link="a"/><child link="b"/><origin rpy="0 0,5 0"/></joint></robot>',
        "joint 'j2', <origin rpy='0 0,5 0'>: not 3 number(s) (a decimal point, spaces)",
    ),
    "a xacro file not expanded": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j2" type="revolute"><parent link="a"/><child link="b"/><origin xyz="${L} 0 0"/>'
        '<limit lower="${-pi}" upper="1" effort="1" velocity="1"/></joint></robot>',
        "joint 'j2', <origin xyz='${L} 0 0'>: a xacro expression; expand the file first",
    ),
    "an origin not finite": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j2" type="continuous"><parent link="a"/><child link="b"/>'
        '<origin xyz="0.3 inf 0"/></joint></robot>',
        "joint 'j2', <origin xyz='0.3 inf 0'>: not finite",
    ),
    "a loop off the chain": (
        '<robot name="r"><link name="a"/><link name="b"/><link name="x"/><link name="y"/><link name="z"/>'
        '<joint name="jz" type="continuous"><parent link="x"/><child link="z"/></joint>'
        '<joint name="j1" type="continuous"><parent link="a"/><child link="b"/></joint>'
        '<joint name="jx" type="continuous"><parent link="y"/><child link="x"/></joint>'
        '<joint name="jy" type="continuous"><parent link="x"/><child link="y"/></joint></robot>',
        "joints 'jx', 'jy' close a loop; a URDF is a tree",
    ),
    "a link not declared": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j1" type="continuous"><parent link="a"/><child link="b"/></joint>'
        '<joint name="j2" type="continuous"><parent link="b"/><child link="c"/></joint></robot>',
        "joint 'j2': its child link 'c' is no <link> in the file",
    ),
    "joints that close a loop": (
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/>'
        '<joint name="j1" type="continuous"><parent link="a"/><child link="b"/></joint>'
        '<joint name="j2" type="continuous"><parent link="b"/><child link="c"/></joint>'
        '<joint name="j3" type="fixed"><parent link="c"/><child link="a"/></joint></robot>',
        "close a loop; a URDF is a tree",
    ),
    "infinite limits": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j2" type="revolute"><parent link="a"/><child link="b"/>'
        '<limit lower="-inf" upper="inf" effort="1" velocity="1"/></joint></robot>',
        "joint 'j2' has limits lower -inf and upper inf; give finite limits, or make it continuous",
    ),
    "only a negative upper limit": (
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j2" type="revolute"><parent link="a"/><child link="b"/>'
        '<limit upper="-0.5" effort="1" velocity="1"/></joint></robot>',
        "joint 'j2' has limits lower 0.0 > upper -0.5 (a bound not given is 0 in URDF)",
    ),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_urdf_is_named(tmp_path, case):
    text, msg = BAD[case]
    p = tmp_path / "r.urdf"
    p.write_text(text)
    with pytest.raises(RobotFileError, match=re.escape(msg)):
        load_robot(p)


def test_numbers_jaxcal_does_not_read_are_not_checked(tmp_path):
    """A fixed joint's axis (the URDF readers ignore it) and the joints another element nests
    (``<gazebo>``, ``<ros2_control>``) may hold what a joint of the chain may not."""
    p = tmp_path / "r.urdf"
    p.write_text(
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/>'
        '<joint name="j1" type="continuous"><parent link="a"/><child link="b"/></joint>'
        '<joint name="f" type="fixed"><parent link="b"/><child link="c"/><origin xyz="0 0 0.1"/><axis xyz="0 0"/>'
        "</joint>"
        '<gazebo><joint name="j1"><origin xyz="${a} 0 0"/></joint></gazebo>'
        '<ros2_control name="s" type="system"><joint name="j1"><limit lower="{-pi}"/></joint></ros2_control></robot>'
    )
    assert load_robot(p).joint_names == ("j1",)


def test_dh_robot_is_not_written_as_urdf(tmp_path):
    from jaxcal import preset, save_robot

    with pytest.raises(RobotFileError, match="written as TOML"):
        save_robot(preset("ur5"), tmp_path / "x.urdf")
    assert not (tmp_path / "x.urdf").exists()


def test_one_limit_given_takes_urdfs_zero_for_the_other(tmp_path):
    """``<limit upper="1">`` is 0..1 (URDF's default lower), not a full turn; a limit element
    without bounds is taken as no limit (±pi)."""
    p = tmp_path / "r.urdf"
    p.write_text(
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/>'
        '<joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>'
        '<limit upper="1.0" effort="1" velocity="1"/></joint>'
        '<joint name="j2" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0.2 0 0"/>'
        '<axis xyz="0 1 0"/><limit effort="1" velocity="1"/></joint></robot>'
    )
    np.testing.assert_allclose(np.asarray(load_robot(p).q_limits), [[0.0, 1.0], [-np.pi, np.pi]])


def test_continuous_joint_and_default_axis(tmp_path):
    """A continuous joint has no limits (±pi for simulation); an axis left out is URDF's x."""
    p = tmp_path / "r.urdf"
    p.write_text(
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/>'
        '<joint name="spin" type="continuous"><parent link="a"/><child link="b"/>'
        '<origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/></joint>'
        '<joint name="tilt" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0.2 0 0" rpy="0 0 0"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>'
    )
    r = load_robot(p)
    np.testing.assert_allclose(np.asarray(r.q_limits), [[-np.pi, np.pi], [-1.0, 1.0]])
    np.testing.assert_allclose(np.asarray(r.axes)[1], [1.0, 0.0, 0.0])
    T = np.asarray(fk(r, np.array([[np.pi / 2, np.pi / 2]])))[0]
    # spin turns the 0.2 m link to +y; tilt about x then turns nothing of a point on x
    np.testing.assert_allclose(T[:3, 3], [0.0, 200.0, 100.0], atol=1e-9)
    # a continuous joint's readings may run over several turns: taken for degrees (a limited
    # joint's ±pi reads the same), the refusal says they may be radians and what to do then
    from jaxcal.calibration import check_angles

    q = np.c_[np.linspace(-12.0, 12.0, 10), np.linspace(-0.9, 0.9, 10)]
    with pytest.raises(DataError, match="if joint 'spin' is a continuous joint whose readings run over several turns"):
        check_angles(r, q)
    with pytest.raises(DataError, match="beyond a full turn and its limits") as e:
        check_angles(r, np.c_[q[:, 0] / 10, np.degrees(q[:, 1]) * 2])
    assert "continuous" not in str(e.value)  # tilt has limits of its own


def test_a_continuous_joints_limits_given_in_the_file_are_its_readings_range(tmp_path):
    """A continuous joint with ``lower`` and ``upper`` (the refusal of readings over several turns
    asks for them) takes them; with one bound, or none, it has none of its own (±pi)."""
    from jaxcal.calibration import check_angles

    def robot(limit):
        p = tmp_path / "r.urdf"
        p.write_text(
            '<robot name="r"><link name="a"/><link name="b"/><link name="c"/>'
            f'<joint name="spin" type="continuous"><parent link="a"/><child link="b"/>{limit}</joint>'
            '<joint name="tilt" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0.2 0 0"/>'
            '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>'
        )
        return load_robot(p)

    wide = robot('<limit lower="-20" upper="20" effort="1" velocity="1"/>')
    np.testing.assert_allclose(np.asarray(wide.q_limits)[0], [-20.0, 20.0])
    q = np.c_[np.linspace(-12.0, 12.0, 10), np.linspace(-0.9, 0.9, 10)]
    check_angles(wide, q)  # radians over several turns, within the file's range
    for limit in ('<limit effort="1" velocity="1"/>', '<limit upper="5" effort="1" velocity="1"/>', ""):
        np.testing.assert_allclose(np.asarray(robot(limit).q_limits)[0], [-np.pi, np.pi])


def test_a_joint_the_calibration_left_keeps_the_files_text(tmp_path):
    """Only the joints whose parameters changed get a new ``<origin>``; a joint left as it was, and
    a unit axis, keep the file's own text (no float noise: ``0.01`` stays ``0.01``)."""
    from lxml import etree

    nominal = tmp_path / "rich.urdf"
    nominal.write_text(RICH, encoding="utf-8")
    r = load_robot(nominal, base_link="base", tip_link="l2")
    dh = np.zeros((2, 7))
    dh[1, 1] = 0.5  # j2's origin moves 0.5 mm along its x
    written = tmp_path / "cal.urdf"
    save_model(Model(r.replace(dh=dh), np.ones((1, 3))), written, template=nominal, base_link="base", tip_link="l2")

    def joint(path, name):
        root = etree.parse(str(path)).getroot()
        return next(el for el in root.findall("joint") if el.get("name") == name)

    for tag in ("origin", "axis"):
        assert joint(written, "j1").find(tag).attrib == joint(nominal, "j1").find(tag).attrib
    assert joint(written, "j2").find("origin").attrib != joint(nominal, "j2").find("origin").attrib
