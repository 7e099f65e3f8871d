"""Robot TOML files: round trip, units at the edge, clear errors."""

import tomllib

import jax.numpy as jnp
import numpy as np
import pytest
import yourdfpy
from numpy.testing import assert_allclose

from jaxcal import Model, Robot, RobotFileError, fk, load_robot, save_robot, to_joint
from jaxcal.robot import PRESETS, preset

PAPER_TOML = """
name = "paper-6r"
convention = "sdh"
length_unit = "m"
angle_unit = "deg"
[[joints]]
theta = 0.0
d = 0.0
a = 0.160
alpha = -90
[[joints]]
theta = -90
d = 0.0
a = 0.580
alpha = 0
[[joints]]
theta = 0
d = 0
a = 0.2
alpha = -90
[[joints]]
theta = 0
d = 0.64
a = 0
alpha = 90
[[joints]]
theta = 0
d = 0.228
a = 0
alpha = -90
[[joints]]
theta = 0
d = 0
a = 0
alpha = 0
[tool]
xyz = [0.0, 0.0, 0.1]
rpy = [0.0, 90.0, 0.0]
"""


@pytest.mark.parametrize("name", list(PRESETS))
def test_roundtrip_presets(name, tmp_path, rng):
    r = preset(name)
    save_robot(r, tmp_path / "r.toml")
    r2 = load_robot(tmp_path / "r.toml")
    assert r2.convention == r.convention and r2.joint_types == r.joint_types and r2.name == r.name
    assert_allclose(np.asarray(r2.dh), np.asarray(r.dh), rtol=0, atol=0)
    Q = jnp.asarray(rng.uniform(-2, 2, (10, r.n_joints)))
    assert_allclose(np.asarray(fk(r2, Q)), np.asarray(fk(r, Q)), atol=1e-9)


def test_units_m_deg_convert_to_mm_rad(tmp_path, rng):
    p = tmp_path / "paper.toml"
    p.write_text(PAPER_TOML)
    r = load_robot(p)
    ref = preset("paper-6r")
    assert_allclose(np.asarray(r.dh), np.asarray(ref.dh), atol=1e-12)
    tool = np.asarray(r.tool)
    assert_allclose(tool[:3, 3], [0, 0, 100.0])
    assert_allclose(tool[:3, :3], [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-15)  # Ry(90 deg)


@pytest.mark.parametrize(
    "edit,msg",
    [
        (lambda s: s.replace('convention = "sdh"', 'convention = "xyz"'), "convention"),
        (lambda s: s.replace('length_unit = "m"', 'length_unit = "inch"'), "length_unit"),
        (lambda s: s.replace("a = 0.580", "a = 'long'"), "joint 2 a"),
        (lambda s: s.replace("a = 0.580\n", ""), "joint 2: missing a"),
        (lambda s: s.replace("a = 0.580", "a = 0.58\nlength = 3"), "joint 2: unknown key"),
        (lambda s: "colour = 'red'\n" + s, "unknown top-level key"),
        (lambda s: s.replace("xyz = [0.0, 0.0, 0.1]", "xyz = [0.0, 0.1]"), "[tool].xyz"),
        (lambda s: s.replace("a = 0.580", "a = nan"), "not finite"),
        (lambda s: s.split("[[joints]]")[0] + "joints = 3\n", "at least one [[joints]]"),
        (lambda s: s.replace("[[joints]]", "[[joints]\n", 1), "not valid TOML"),
        (lambda s: '{"robot": "paper-6r", "heldout_rms_mm": 0.1}\n', "a calibrate --json report"),
    ],
)
def test_bad_files_name_the_problem(tmp_path, edit, msg):
    p = tmp_path / "bad.toml"
    p.write_text(edit(PAPER_TOML))
    with pytest.raises(RobotFileError, match=None) as e:
        load_robot(p)
    assert msg in str(e.value)


def test_missing_file():
    with pytest.raises(RobotFileError, match="not found"):
        load_robot("/nonexistent/robot.toml")


def test_constructor_validation():
    with pytest.raises(RobotFileError, match="shape"):
        Robot(np.zeros((6, 3)))
    with pytest.raises(RobotFileError, match="joint 2: theta is not finite"):
        Robot(np.array([[0, 0, 0, 0], [np.nan, 0, 0, 0.0]]))
    with pytest.raises(RobotFileError, match="base is not a rigid transform"):
        Robot(np.zeros((2, 4)), base=2 * np.eye(4))
    with pytest.raises(RobotFileError, match="type"):
        Robot(np.zeros((2, 4)), joint_types=("R", "X"))


def test_limits_left_out_are_the_same_in_code_and_file(tmp_path):
    """A turn either way for a revolute joint, a metre (not pi mm) for a prismatic one, whether the
    robot is built in Python or read from a file without limits."""
    p = tmp_path / "rp.toml"
    joint = "theta = 0\nd = 0\na = 100\nalpha = 0\n"
    p.write_text(f'convention = "sdh"\n[[joints]]\n{joint}[[joints]]\ntype = "P"\n{joint}')
    want = [[-np.pi, np.pi], [-1000.0, 1000.0]]
    assert_allclose(np.asarray(Robot(np.zeros((2, 4)), joint_types=("R", "P")).q_limits), want)
    assert_allclose(np.asarray(load_robot(p).q_limits), want)


def test_limits_not_given_are_not_written_as_limits(tmp_path):
    """A robot given no limits (the UR presets: +-pi is their sampling range) is written without
    them, in TOML (no ``limits`` key) and in a URDF (revolute joints continuous, as yourdfpy reads
    them), and reads back as given none; a joint given limits keeps them in both."""
    lim = np.tile([-np.pi, np.pi], (6, 1))
    lim[2] = -2.5, 2.5  # one joint given limits
    robot = preset("ur5").replace(q_limits=lim)
    save_robot(robot, tmp_path / "u.toml")
    joints = tomllib.loads((tmp_path / "u.toml").read_text())["joints"]
    assert ["limits" in j for j in joints] == [False, False, True, False, False, False]
    assert joints[2]["limits"] == [-2.5, 2.5]
    save_robot(to_joint(robot), tmp_path / "u.urdf")
    urdf = yourdfpy.URDF.load(str(tmp_path / "u.urdf"), build_scene_graph=False, load_meshes=False)
    kinds = [urdf.joint_map[n].type for n in robot.joint_names]
    assert kinds == ["continuous", "continuous", "revolute", "continuous", "continuous", "continuous"]
    assert (urdf.joint_map["q3"].limit.lower, urdf.joint_map["q3"].limit.upper) == (-2.5, 2.5)
    for path in ("u.toml", "u.urdf"):
        back = load_robot(tmp_path / path)
        assert back.limits_given().tolist() == [False, False, True, False, False, False]
        assert_allclose(np.asarray(back.q_limits), lim)
    # limits a file gives that happen to be the defaults (a xacro ${pi}) are limits all the same
    text = (
        (tmp_path / "u.toml")
        .read_text()
        .replace('type = "R"\n', 'type = "R"\nlimits = [-3.141592653589793, 3.141592653589793]\n', 1)
    )
    (tmp_path / "pi.toml").write_text(text)
    pi = load_robot(tmp_path / "pi.toml")
    assert pi.limits_given().tolist() == [True, False, True, False, False, False]
    save_robot(pi, tmp_path / "pi2.toml")
    save_robot(to_joint(pi), tmp_path / "pi2.urdf")
    for path in ("pi2.toml", "pi2.urdf"):
        assert load_robot(tmp_path / path).limits_given().tolist() == [True, False, True, False, False, False]
    urdf = yourdfpy.URDF.load(str(tmp_path / "pi2.urdf"), build_scene_graph=False, load_meshes=False)
    assert urdf.joint_map["q1"].type == "revolute" and urdf.joint_map["q1"].limit.upper == np.pi


def test_constructor_does_not_mutate_inputs():
    dh = np.zeros((2, 4))
    before = dh.copy()
    r = Robot(dh)
    r2 = r.with_dh_delta(jnp.ones((2, 4)))
    assert np.array_equal(dh, before) and np.array_equal(np.asarray(r.dh), before)
    assert np.array_equal(np.asarray(r2.dh), np.ones((2, 4)))


def test_a_robot_keeps_its_own_copy_of_the_callers_arrays():
    """A robot built from a NumPy table, frames and limits is not changed by the caller's later
    writes to them (a notebook editing one buffer for several robots): JAX on CPU may alias a
    float64 NumPy buffer, and the forward kinematics followed the edit."""

    def aligned(a):  # on a 64-byte boundary, where JAX on CPU takes a NumPy buffer without a copy
        buf = np.empty(np.size(a) + 8)
        out = buf[(-buf.ctypes.data % 64) // 8 :][: np.size(a)].reshape(np.shape(a))
        out[...] = a
        return out

    ur5 = preset("ur5")
    dh, base, tool, lim = (aligned(a) for a in (ur5.dh, np.eye(4), np.eye(4), ur5.q_limits))
    r = Robot(dh, base=base, tool=tool, q_limits=lim)
    q = np.zeros((1, 6))
    before = np.array(fk(r, q))
    dh[1, 2] += 100.0
    base[0, 3], tool[2, 3], lim[:] = 50.0, 7.0, 0.0
    assert np.array_equal(np.asarray(fk(r, q)), before)
    assert np.array_equal(np.asarray(r.q_limits), np.asarray(ur5.q_limits))
    model = Model(r, points := aligned(np.ones((2, 3))))
    points[:] = 9.0
    assert np.array_equal(np.asarray(model.points), np.ones((2, 3)))


def test_training_ranges_round_trip_in_the_files_units(tmp_path):
    """The joint ranges a model was fitted on, written in a TOML file in metres and degrees, read
    back in mm and rad; a nominal file has none."""
    from jaxcal.robot import read_training_ranges

    r = preset("ur5").replace(units=("m", "deg"))
    ranges = {n: (-0.5 - i, 0.25 * i) for i, n in enumerate(r.joint_names)}
    save_robot(r, tmp_path / "r.toml", training_ranges=ranges)
    assert "training_ranges" in (tmp_path / "r.toml").read_text()
    back = read_training_ranges(tmp_path / "r.toml")
    assert back.keys() == ranges.keys()
    for n in ranges:
        assert back[n] == pytest.approx(ranges[n], rel=1e-14)
    save_robot(r, tmp_path / "plain.toml")
    assert read_training_ranges(tmp_path / "plain.toml") is None


@pytest.mark.parametrize(
    "numbers, ok", [([1, 3], True), ([3], False), ([1, 1], False), ([0, 2], False), ([1, True], False)]
)
def test_point_numbers_are_checked_against_the_points(tmp_path, numbers, ok):
    """``point_numbers`` names each point's number in the data file: one distinct number >= 1 per
    point, or the file is refused naming the key; a file without points' numbers records none."""
    from jaxcal.robot import read_point_numbers

    text = "points = [[0.01, 0.0, 0.0], [0.0, 0.02, 0.0]]\n"  # top-level keys come before the tables
    path = tmp_path / "p.toml"
    path.write_text(text + f"point_numbers = {str(numbers).replace('True', 'true')}\n" + PAPER_TOML)
    if ok:
        assert read_point_numbers(path) == tuple(numbers) and load_robot(path).n_joints == 6
    else:
        with pytest.raises(RobotFileError, match="point_numbers"):
            load_robot(path)
    path.write_text(text + PAPER_TOML)
    assert read_point_numbers(path) is None
    path.write_text("point_numbers = [1]\n" + PAPER_TOML)  # numbers of points the file does not hold
    with pytest.raises(RobotFileError, match="point_numbers"):
        load_robot(path)


def test_point_numbers_are_checked_when_written(tmp_path):
    """Writing refuses numbers that do not name each point once, as reading would."""
    from jaxcal.robot import read_point_numbers

    r = preset("paper-6r")
    pts = np.array([[10.0, 0.0, 0.0], [0.0, 20.0, 0.0]])
    for bad in ([3], [1, 1], [0, 2]):
        with pytest.raises(RobotFileError, match="point_numbers"):
            save_robot(r, tmp_path / "p.toml", points=pts, point_numbers=bad)
    assert not (tmp_path / "p.toml").exists()
    save_robot(r, tmp_path / "p.toml", points=pts, point_numbers=[4, 2])
    assert read_point_numbers(tmp_path / "p.toml") == (4, 2)


def test_save_robot_refuses_what_it_cannot_write_or_load_back(tmp_path):
    """A .yaml name would be read back as UR's kinematics file; a calibration result is not a
    robot; a folder is not a file: each refused, naming the path, nothing written."""
    import jaxcal

    r = preset("ur5")
    with pytest.raises(RobotFileError, match=r"a UR kinematics file \(.yaml\) is written by jaxcal.save_ur_kinematics"):
        save_robot(r, tmp_path / "cal.yaml")
    sim = jaxcal.simulate(r, n_poses=30, seed=1, sigma_pos=0.0)
    res = jaxcal.calibrate(r, sim.q[0], sim.measured[0, :, :3, 3])
    with pytest.raises(RobotFileError, match="save_robot takes a jaxcal.Robot"):
        save_robot(res, tmp_path / "cal.toml")
    with pytest.raises(jaxcal.DataError, match="is a directory"):
        save_robot(r, tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_an_angle_beyond_a_whole_turn_is_written_so_that_it_reads_back(tmp_path, rng):
    """The reader refuses a twist or offset beyond a whole turn in radians (likely degrees); one
    that a robot holds is written within a turn, the same frames, and the file reads back."""
    dh = np.asarray(preset("ur5").dh).copy()
    dh[0, 0], dh[2, 3] = 7.0, -20.0
    r = preset("ur5").replace(dh=dh)
    save_robot(r, tmp_path / "r.toml")
    back = load_robot(tmp_path / "r.toml")
    q = rng.uniform(-2, 2, (5, 6))
    assert_allclose(np.asarray(fk(back, q)), np.asarray(fk(r, q)), atol=1e-9)
    assert np.abs(np.asarray(back.dh)[:, [0, 3]]).max() <= np.pi + 1e-12
