"""Forward kinematics (eq. 1-2) against an independent NumPy/SciPy construction."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_dh, random_transform
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from jaxcal import Robot, fk, fk_frames, to_mdh, to_sdh
from jaxcal import kinematics as K
from jaxcal.robot import PRESETS, preset


def _rot(axis, angle):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(np.array(axis, float) * angle).as_matrix()
    return T


def _trans(v):
    T = np.eye(4)
    T[:3, 3] = v
    return T


def ref_link(conv, th, d, a, al):
    """Elementary-motion composition, written independently of jaxcal."""
    if conv == "sdh":
        return _rot([0, 0, 1], th) @ _trans([0, 0, d]) @ _trans([a, 0, 0]) @ _rot([1, 0, 0], al)
    return _rot([1, 0, 0], al) @ _trans([a, 0, 0]) @ _rot([0, 0, 1], th) @ _trans([0, 0, d])


def ref_fk(conv, dh, types, base, tool, q):
    T = base.copy()
    for (th, d, a, al), t, qi in zip(dh, types, q):
        T = T @ ref_link(conv, th + qi * (t == "R"), d + qi * (t == "P"), a, al)
    return T @ tool


@pytest.mark.parametrize("conv", ["sdh", "mdh"])
def test_link_matches_elementary_motions(conv, rng):
    P = random_dh(rng, 50)
    got = np.asarray(K.LINKS[conv](*P.T))
    for p, g in zip(P, got):
        assert_allclose(g, ref_link(conv, *p), atol=1e-12)


@pytest.mark.parametrize("conv", ["sdh", "mdh"])
def test_fk_matches_reference_with_prismatic_base_tool(conv, rng):
    dh = random_dh(rng, 7)
    types = ("R", "R", "P", "R", "R", "P", "R")
    base, tool = random_transform(rng), random_transform(rng)
    robot = Robot(dh, convention=conv, joint_types=types, base=base, tool=tool)
    Q = rng.uniform(-2, 2, (20, 7)) * np.where(np.array(types) == "P", 100.0, 1.0)
    got = np.asarray(fk(robot, jnp.asarray(Q)))
    for q, g in zip(Q, got):
        assert_allclose(g, ref_fk(conv, dh, types, base, tool, q), atol=1e-9)


@pytest.mark.parametrize("conv", ["sdh", "mdh"])
def test_every_frame_matches_reference(conv, rng):
    """fk_frames: T_i = base A_1 ... A_i for every i (not only the last), leading axes kept."""
    dh = random_dh(rng, 5)
    types = ("R", "P", "R", "R", "P")
    base = random_transform(rng)
    robot = Robot(dh, convention=conv, joint_types=types, base=base)
    Q = rng.uniform(-2, 2, (2, 3, 5))
    got = np.asarray(fk_frames(robot, jnp.asarray(Q)))
    assert got.shape == (2, 3, 5, 4, 4)
    for idx in np.ndindex(2, 3):
        for i in range(5):
            want = ref_fk(conv, dh[: i + 1], types[: i + 1], base, np.eye(4), Q[idx][: i + 1])
            assert_allclose(got[idx][i], want, atol=1e-9)


def test_prismatic_joint_translates_along_z(rng):
    r = Robot(np.zeros((1, 4)), joint_types=("P",))
    assert_allclose(np.asarray(fk(r, jnp.array([12.5])))[:3, 3], [0, 0, 12.5])


def test_batched_shapes_jit_and_vmap(rng):
    r = preset("paper-6r")
    Q = jnp.asarray(rng.uniform(-1, 1, (3, 5, 6)))
    assert fk(r, Q).shape == (3, 5, 4, 4)
    assert fk_frames(r, Q).shape == (3, 5, 6, 4, 4)
    flat = fk(r, Q.reshape(-1, 6))
    assert_allclose(np.asarray(jax.jit(fk)(r, Q)).reshape(-1, 4, 4), np.asarray(flat), atol=1e-12)
    assert_allclose(np.asarray(jax.vmap(lambda q: fk(r, q))(Q.reshape(-1, 6))), np.asarray(flat), atol=1e-12)
    # frames: the last frame times the tool is the end pose
    assert_allclose(np.asarray(fk_frames(r, Q)[..., -1, :, :] @ r.tool), np.asarray(fk(r, Q)))


def test_vmap_over_robots(rng):
    robots = [Robot(random_dh(rng)) for _ in range(4)]
    stacked = jax.tree.map(lambda *x: jnp.stack(x), *robots)
    q = jnp.asarray(rng.uniform(-1, 1, 6))
    got = jax.vmap(lambda r: fk(r, q))(stacked)
    for r, g in zip(robots, got):
        assert_allclose(np.asarray(g), np.asarray(fk(r, q)), atol=1e-12)


@pytest.mark.parametrize("name", list(PRESETS))
def test_sdh_mdh_conversion_presets(name, rng):
    r = preset(name)
    other = to_mdh(r) if r.convention == "sdh" else to_sdh(r)
    assert other.convention != r.convention
    Q = jnp.asarray(rng.uniform(-3, 3, (50, r.n_joints)))
    assert_allclose(np.asarray(fk(other, Q)), np.asarray(fk(r, Q)), atol=1e-9)
    back = to_sdh(other) if r.convention == "sdh" else to_mdh(other)
    assert_allclose(np.asarray(fk(back, Q)), np.asarray(fk(r, Q)), atol=1e-9)


def test_sdh_mdh_conversion_random(rng):
    for _ in range(10):
        r = Robot(
            random_dh(rng),
            base=random_transform(rng),
            tool=random_transform(rng),
            joint_types=tuple(rng.choice(["R", "P"], 6)),
        )
        Q = jnp.asarray(rng.uniform(-3, 3, (20, 6)))
        assert_allclose(np.asarray(fk(to_mdh(r), Q)), np.asarray(fk(r, Q)), atol=1e-9)


def test_paper_arm_home_pose():
    """Table 1 arm at q = 0, by hand: joint 2's -pi/2 offset points the 580 mm upper arm up;
    x = a1 + d4 = 800, y = d5 = 228, z = a2 + a3 = 780 (mm)."""
    T = np.asarray(fk(preset("paper-6r"), jnp.zeros(6)))
    assert_allclose(T[:3, 3], [800.0, 228.0, 780.0], atol=1e-9)


def test_ur5_home_pose():
    """UR5 at q = 0 (published table): x = a2 + a3 = -817.25, y = -(d4 + d6) = -191.45,
    z = d1 - d5 = -5.491 (mm)."""
    T = np.asarray(fk(preset("ur5"), jnp.zeros(6)))
    assert_allclose(T[:3, 3], [-817.25, -191.45, 89.159 - 94.65], atol=1e-9)


def test_dh_conversions_of_a_joint_frame_robot_are_jaxcal_errors():
    """Every refusal jaxcal means is a JaxcalError (a RobotFileError here), not a bare ValueError."""
    from jaxcal import RobotFileError, to_joint
    from jaxcal.robot import preset

    r = to_joint(preset("ur5"))
    for convert in (to_mdh, to_sdh):
        with pytest.raises(RobotFileError, match="needs a DH robot; 'ur5' is described by joint frames"):
            convert(r)
