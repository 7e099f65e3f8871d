"""The joint-frame error model (URDF robots): its analytic identification Jacobian against
``jax.jacfwd``, its base set naming what is absorbed, and a calibration that recovers a
perturbed URDF whose data come from yourdfpy's kinematics."""

import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yourdfpy
from helpers import load_urdf, random_transform, tilted_arm, tilted_arm_links, urdf_chain, urdf_points

from jaxcal import Options, calibrate, load_robot
from jaxcal.measurements import tiago_paths
from jaxcal.model import Layout, Model, apply, errors, predict, residual_and_jacobian

URDF, _ = tiago_paths()


@pytest.fixture(scope="module")
def tiago():
    return load_robot(URDF)


def _q(robot, rng, k):
    lim = np.asarray(robot.q_limits)
    return lim[:, 0] + rng.uniform(size=(k, robot.n_joints)) * (lim[:, 1] - lim[:, 0])


@pytest.mark.parametrize("n_points", [0, 1, 3], ids=["pose", "point", "3 points"])
def test_jacobian_matches_autodiff_away_from_zero(tiago, n_points):
    """At a nonzero parameter vector (the rotation corrections' chart is not the identity there)."""
    rng = np.random.default_rng(n_points)
    model = Model(tiago, rng.normal(size=(n_points, 3)) * 50 if n_points else None)
    layout = Layout.of(tiago, base=True, tool=True, n_points=n_points)
    x = jnp.asarray(rng.normal(size=layout.size) * 0.05)
    q = jnp.asarray(_q(tiago, rng, 5))

    @jax.jit  # one program, not one per operation
    def both(x, x_target):
        target = predict(apply(model, layout, x_target), q)
        J_ad = jax.jacfwd(lambda x_: errors(apply(model, layout, x_), q, target))(x)
        return residual_and_jacobian(model, layout, x, q, target)[1], J_ad

    J, J_ad = both(x, jnp.asarray(rng.normal(size=layout.size) * 0.05))
    np.testing.assert_allclose(np.asarray(J), np.asarray(J_ad), atol=1e-9)
    assert layout.units()[:8] == ["mm", "mm", "mm", "mm", "rad", "rad", "rad", "rad"]  # torso offset is a length


def test_base_set_names_what_is_absorbed(tiago):
    """A joint's rotation about its own axis is its offset; the prismatic torso's shift along its
    axis is its offset too; both are named, the earlier parameter kept."""
    rng = np.random.default_rng(2)
    from jaxcal.identifiability import analyze
    from jaxcal.model import jacobian

    layout = Layout.of(tiago, n_points=1)
    J = np.asarray(jax.jit(lambda q: jacobian(Model(tiago, np.zeros((1, 3))), layout, q))(_q(tiago, rng, 40)))
    ident = analyze(J.reshape(-1, layout.size), layout.names())
    reasons = ident.reasons()
    assert "rz3" in reasons and "offset3" in reasons["rz3"]  # arm_2: axis z, so rz is the offset
    assert "z1" in reasons  # the torso's shift along z is its offset


def _perturbed_urdf(text, rng):
    """The URDF with every joint origin's xyz moved by up to a millimetre and its rpy by up to
    a milliradian, edited as text (independently of jaxcal's writer)."""

    def moved(values):
        return " ".join(repr(float(v) + rng.uniform(-1e-3, 1e-3)) for v in values.split())

    def move(m):
        return f'<origin xyz="{moved(m.group(1))}" rpy="{moved(m.group(2))}"'

    return re.sub(r'<origin xyz="([^"]*)" rpy="([^"]*)"', move, text)


def test_recovers_a_perturbed_urdf_from_four_points(tmp_path, tiago):
    rng = np.random.default_rng(2025)
    true_path = tmp_path / "true.urdf"
    true_path.write_text(_perturbed_urdf(URDF.read_text(), rng))
    markers = rng.normal(size=(4, 3)) * 0.08  # on the tip link, metres
    base = np.eye(4)
    base[:3, 3] = [0.3, -0.2, 0.1]
    u = yourdfpy.URDF.load(str(true_path), build_scene_graph=True, load_meshes=False)

    def truth(q):
        out = []
        for row in q:
            cfg = dict(zip(tiago.joint_names, row * np.array([1e-3] + [1.0] * 7)))
            u.update_cfg(cfg)
            T = base @ np.array(u.get_transform(frame_to="wrist_ft_tool_link", frame_from="base_footprint"))
            out.append((T[:3, :3] @ markers.T).T + T[:3, 3])
        return np.stack(out) * 1000.0

    q, q_val = _q(tiago, rng, 60), _q(tiago, rng, 20)
    meas = truth(q) + rng.normal(size=(60, 4, 3)) * 1e-4
    res = calibrate(tiago, q, meas, params="all", estimate_base=True, estimate_tool=True)
    assert res.converged
    err = np.linalg.norm(np.asarray(predict(res.model, q_val)) - truth(q_val), axis=-1)
    nominal = Model(tiago, np.asarray(res.model.points))
    before = np.linalg.norm(np.asarray(predict(nominal, q_val)) - truth(q_val), axis=-1)
    assert before.max() > 100 * err.max()  # the perturbation mattered
    assert err.max() < 5e-3, err.max()  # recovered to the noise level (0.1 um per coordinate)


def test_frames_end_in_the_tool_pose(tiago):
    """``fk_frames``' last frame (the last joint after its motion) times the tool is ``fk``."""
    from jaxcal import fk, fk_frames

    q = _q(tiago, np.random.default_rng(4), 5)
    frames = np.asarray(fk_frames(tiago, q))
    assert frames.shape == (5, tiago.n_joints, 4, 4)
    np.testing.assert_allclose(frames[:, -1] @ np.asarray(tiago.tool), np.asarray(fk(tiago, q)), atol=1e-9)


def test_the_turn_along_a_joints_axis_is_the_one_left_out(tmp_path):
    """A joint's offset is, to first order, the turn of its origin about the joint's axis: for an
    axis along x it is ``rx``, for an axis tilted a little off x nearly ``rx``. The base set
    leaves out the turn most aligned with the axis, so the kept set stays well conditioned; the
    plain order (offset, x, y, z, rx, ry, rz), which leaves out ``rz``, keeps a near-twin of the
    offset for the tilted axis (a real case: a humanoid's elbow in example-robot-data)."""
    from jaxcal.calibration import _core as core
    from jaxcal.identifiability import DOMINANCE, analyze
    from jaxcal.model import Layout

    path = tmp_path / "r.urdf"
    path.write_text(tilted_arm(4))
    robot = load_robot(path)
    q = np.random.default_rng(5).uniform(-2, 2, (40, 4))
    layout = Layout.of(robot, base=True, tool=True, n_points=1)
    J = core.analyse(core.nominal_model(robot, layout), layout, q)[0]
    ident = core.base_set(J, layout, robot)
    why = ident.reasons()
    # (the first joint's frame is the base's to absorb, the last's the point's)
    assert "rx2" in why and "offset2" not in why  # x axis: rx
    assert "rx3" in why and "offset3" not in why  # nearly x: rx, not rz

    def condition(base):
        Jb = J.reshape(-1, layout.size)[:, list(base)]
        return np.linalg.cond(Jb / np.linalg.norm(Jb, axis=0))

    plain = analyze(
        J.reshape(-1, layout.size), layout.names(), priority=list(layout.frames) + list(range(layout.n_kin))
    )
    names = layout.names()
    assert "rx3" in [names[i] for i in plain.base]  # the near-twin kept
    a, b = (J.reshape(-1, layout.size)[:, names.index(n)] for n in ("offset3", "rx3"))
    assert abs(a @ b) / np.linalg.norm(a) / np.linalg.norm(b) > 0.99  # a twin indeed
    assert condition(ident.base) < condition(plain.base)
    # the exchange after the order: no held joint-frame parameter carries more than DOMINANCE
    # times a kept one, in unit-norm columns (an independent least squares)
    Jm = J.reshape(-1, layout.size)
    norms = np.linalg.norm(Jm, axis=0)
    Jn = Jm / np.where(norms > 0, norms, 1.0)
    # a joint's offset is never traded: the shifts and turns of the origins among themselves
    kin = [i for i in range(layout.n_kin) if norms[i] > 1e-8 * norms.max() and not names[i].startswith("offset")]

    def largest(base):
        held = [i for i in kin if i not in base]
        beta = np.linalg.lstsq(Jn[:, list(base)], Jn[:, held], rcond=None)[0]
        return np.abs(beta[[k for k, i in enumerate(base) if i in kin]]).max()

    ordered = analyze(Jm, names, priority=list(layout.frames) + core.kin_order(robot, layout))
    assert largest(ident.base) <= DOMINANCE + 1e-9
    assert largest(ordered.base) > 10  # the order alone: a held turn shows 10 times over in a kept shift
    assert condition(ident.base) < condition(ordered.base) / 5


@pytest.mark.parametrize("seed", [0, 1])
def test_the_links_between_the_measured_points_are_written_where_the_arm_has_them(tmp_path, seed):
    """The five-joint arm of the test above (one axis tilted off x), every origin moved by up to
    3 mm and 3 mrad, three points measured by yourdfpy on the moved file (0.01 mm noise). The
    points fix only the chain as a whole: a held parameter with a near twin kept would show its
    error there amplified, and the written file would put the links tens of mm from the arm
    while fitting the points as well. Every link's frame in the written file, read by yourdfpy,
    lies within 8 mm and 1.5 degrees of the moved file's."""
    r, far, turn = tilted_arm_links(tmp_path, seed)
    assert r.converged and r.after["pos_rms_mm"] < 0.03
    assert far < 8.0 and turn < 1.5, (far, turn)


def test_joint_zeros_alone_are_fitted_by_the_offsets_set():
    """An xArm7 whose only errors are its joints' zeros (up to 10 mrad), three points measured by
    yourdfpy (0.01 mm noise): ``params="offsets"`` fits them to the noise. The exchange after the
    parameter order never trades a joint's offset for a shift or turn of its origin, which the
    offsets set would then leave out."""
    path = Path(__file__).resolve().parent / "data" / "urdf" / "xarm7.urdf"
    truth = load_urdf(path)
    names, lim = urdf_chain(truth, "link_base", "link7")
    rng = np.random.default_rng(0)
    zeros = rng.uniform(-0.01, 0.01, len(names))
    frame = random_transform(rng, 1000.0)
    q = lim[:, 0] + rng.uniform(size=(60, len(names))) * (lim[:, 1] - lim[:, 0])
    on_tip = ([0.05, 0, 0.02], [0, 0.04, 0.03], [-0.03, -0.02, 0.06])
    moved = [urdf_points(truth, names, q + zeros, "link_base", "link7", np.array(v)) for v in on_tip]
    p = np.stack([m @ frame[:3, :3].T + frame[:3, 3] for m in moved], 1)
    robot = load_robot(path, base_link="link_base", tip_link="link7")
    r = calibrate(robot, q, p + rng.normal(scale=0.01, size=p.shape), Options(params="offsets"))
    assert r.converged and r.after["pos_rms_mm"] < 0.03
