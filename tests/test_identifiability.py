"""Identifiability analysis: rank deficiencies that follow from the arms' geometry, the
combination matrix against plain least squares, the CRLB against Monte Carlo, observability
indices against a hand computation.

Geometry used below (SDH link `Rz(theta) Tz(d) Tx(a) Rx(alpha)`, end point at the last frame's
origin, base and tool identity):

* consecutive parallel joint axes (`alpha_i = 0`): `d_i` shifts along `z_{i-1}`, `d_{i+1}` along
  `z_i`, the same direction in every pose, so only `d_i + d_{i+1}` is observable;
* a base twist (measurement frame -> frame 0) contains a rotation about and a translation along
  joint 1's axis `z_0`: exactly what `theta_1` and `d_1` do;
* a tool twist (in the flange frame) absorbs everything that sits *after* `q_n` in the chain:
  in SDH all four parameters of the last joint (`Rz(dtheta)` and `Tz(dd)` commute with
  `Rz(q_n)`), i.e. the tool components z, rz, x, rx; tool y and ry stay identifiable;
* position-only: a rotation about an axis through the measured point moves nothing, so with the
  point at a wrist centre the wrist's `theta`/`alpha` columns are zero, and tool rotations about
  the tool point are never seen.
"""

import functools

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_dh
from numpy.testing import assert_allclose, assert_array_equal

import jaxcal
from jaxcal import error_model as E
from jaxcal.errors import DataError
from jaxcal.identifiability import analyze, crlb, row_sigmas


def _poses(robot, n=50, seed=7):
    lim = np.asarray(robot.q_limits)
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, robot.n_joints))


@functools.cache
def _jac(name, position_only=False, base=False, tool=False):
    robot = jaxcal.preset(name)
    J = E.identification_jacobian(robot, jnp.asarray(_poses(robot)), position_only=position_only, base=base, tool=tool)
    return np.asarray(J), tuple(E.param_names(robot, base=base, tool=tool))


def _analyze(name, **kw):
    J, names = _jac(name, **kw)
    return analyze(J, names)


def _names(ident, idx):
    return tuple(ident.names[i] for i in idx)


def test_paper_full_pose_parallel_axes_2_3():
    """alpha_2 = 0: axes 2 and 3 are parallel, so d2 and d3 both shift along z1 = z2.
    Rank 23 of 24; the earlier parameter d2 is kept and estimates d2 + d3."""
    J, names = _jac("paper-6r")
    Jf = J.reshape(-1, J.shape[-1])
    assert_allclose(Jf[:, names.index("d2")], Jf[:, names.index("d3")], atol=1e-12)
    A = analyze(J, names)
    assert (A.rank, len(A.names)) == (23, 24)
    assert _names(A, A.fixed) == ("d3",)
    assert A.base == tuple(i for i in range(24) if i != names.index("d3"))
    assert A.unidentifiable == ()
    assert A.combinations == ("d2 + d3",)
    C = A.combination_matrix
    assert C.shape == (23, 24)
    assert_allclose(C[A.base.index(names.index("d2")), names.index("d3")], 1.0, atol=1e-9)
    assert_allclose(C[:, list(A.base)], np.eye(23))
    assert A.singular_values.shape == (24,) and np.all(np.diff(A.singular_values) <= 0)
    assert A.singular_values[-1] < 1e-12 < A.singular_values[-2]


def test_paper_base_absorbs_theta1_and_d1():
    """The base twist's rz (rotation about z0 through the origin) and z (translation along z0) are
    joint 1's theta and d. 24 + 6 - 1 (d2/d3) - 2 = rank 27 of 30; base x, y, rx, ry stay."""
    A = _analyze("paper-6r", base=True)
    assert (A.rank, len(A.names)) == (27, 30)
    assert _names(A, A.fixed) == ("d3", "base_z", "base_rz")
    assert A.combinations == ("theta1 + base_rz", "d1 + base_z", "d2 + d3")


def test_paper_tool_absorbs_last_joint():
    """In SDH the whole last link Rz(theta6) Tz(d6) Tx(a6) Rx(alpha6) commutes past q6 into the
    tool frame: theta6 = tool rz, d6 = tool z, a6 = tool x, alpha6 = tool rx (tool identity).
    24 + 6 - 1 - 4 = rank 25 of 30."""
    A = _analyze("paper-6r", tool=True)
    assert (A.rank, len(A.names)) == (25, 30)
    assert _names(A, A.fixed) == ("d3", "tool_x", "tool_z", "tool_rx", "tool_rz")
    assert A.combinations == ("d2 + d3", "theta6 + tool_rz", "d6 + tool_z", "a6 + tool_x", "alpha6 + tool_rx")


def test_paper_base_and_tool():
    """Both deficiencies add up: 24 + 12 - 1 - 2 - 4 = rank 29 of 36."""
    A = _analyze("paper-6r", base=True, tool=True)
    assert (A.rank, len(A.names)) == (29, 36)
    assert _names(A, A.fixed) == ("d3", "base_z", "base_rz", "tool_x", "tool_z", "tool_rx", "tool_rz")
    assert A.combinations == (
        "theta1 + base_rz",
        "d1 + base_z",
        "d2 + d3",
        "theta6 + tool_rz",
        "d6 + tool_z",
        "a6 + tool_x",
        "alpha6 + tool_rx",
    )


def test_paper_position_only_wrist_centre():
    """Position only, the point is o6 = o5 = o4 + 228 z4 (a4 = a5 = a6 = d6 = 0): the wrist centre.
    theta5 (axis z4 through o4), alpha5, theta6, alpha6 (axes through the point) move nothing.
    theta4 rotates about z3 and moves the point by 228 x4, exactly as a4 / 228 does; alpha4 moves
    it by -228 z3, as d4 does. Rank 24 - 4 - 1 - 2 = 17."""
    A = _analyze("paper-6r", position_only=True)
    assert (A.rank, len(A.names)) == (17, 24)
    assert A.unidentifiable == ("theta5", "alpha5", "theta6", "alpha6")
    assert _names(A, A.fixed) == ("d3", "a4", "alpha4", "theta5", "alpha5", "theta6", "alpha6")
    assert A.combinations == ("d2 + d3", "theta4 + 0.004386 a4", "d4 - 228 alpha4")
    C, n = A.combination_matrix, A.names
    assert_allclose(C[A.base.index(n.index("theta4")), n.index("a4")], 1 / 228, rtol=1e-9)
    assert_allclose(C[A.base.index(n.index("d4")), n.index("alpha4")], -228, rtol=1e-9)
    # unidentifiable columns absorb nothing and are absorbed by nothing
    assert np.all(C[:, [n.index(p) for p in A.unidentifiable]] == 0)


def test_position_only_tool_rotation_not_observable():
    """A tool rotation turns about the tool point (tool = identity), which is the measured
    point: tool rx, ry, rz have zero columns. Tool x and z absorb a6 and d6 (rank 18 of 30);
    with the base too, 22 of 36."""
    A = _analyze("paper-6r", position_only=True, tool=True)
    assert (A.rank, len(A.names)) == (18, 30)
    assert A.unidentifiable == ("theta5", "alpha5", "theta6", "alpha6", "tool_rx", "tool_ry", "tool_rz")
    assert A.combinations[-2:] == ("d6 + tool_z", "a6 + tool_x")
    B = _analyze("paper-6r", position_only=True, base=True, tool=True)
    assert (B.rank, len(B.names)) == (22, 36)
    assert B.combinations[:2] == ("theta1 + base_rz", "d1 + base_z")


def test_puma560():
    """PUMA 560: alpha2 = 0 as on the paper arm (rank 23 of 24, d2 + d3). Position only the point
    is the wrist centre o4 = o3 + 431.8 z3: theta4..alpha6 but d4, a4 have zero columns
    (6 of them). alpha3 moves the point by 431.8 z2, like d2, d3; theta3 moves it by
    20.3 z3 - 431.8 x3, a combination of d4 (z3) and a3 (x3). Rank 24 - 6 - 3 = 15."""
    A = _analyze("puma560")
    assert (A.rank, _names(A, A.fixed), A.combinations) == (23, ("d3",), ("d2 + d3",))
    P = _analyze("puma560", position_only=True)
    assert (P.rank, len(P.names)) == (15, 24)
    assert P.unidentifiable == ("theta4", "alpha4", "theta5", "alpha5", "theta6", "alpha6")
    assert _names(P, P.fixed) == ("d3", "alpha3", "theta4", "d4", "alpha4", "theta5", "alpha5", "theta6", "alpha6")
    assert P.combinations == ("d2 + d3 + 431.8 alpha3", "theta3 + 0.04926 d4", "a3 + 21.27 d4")
    C, n = P.combination_matrix, P.names
    assert_allclose(C[P.base.index(n.index("theta3")), n.index("d4")], 1 / 20.3, rtol=1e-9)
    assert_allclose(C[P.base.index(n.index("a3")), n.index("d4")], 431.8 / 20.3, rtol=1e-9)


def test_ur5_three_parallel_axes():
    """UR5: alpha2 = alpha3 = 0, axes 2, 3, 4 are parallel: d2, d3, d4 all shift along the same
    direction, two deficiencies (rank 22 of 24); with base and tool 22 + 12 - 2 - 4 = 28 of 36.
    Position only the point o6 lies on axis 6 (d6 = 82.3, a6 = 0): theta6, alpha6 vanish and
    theta5, alpha5 trade with a5, d5 (lever 82.3)."""
    A = _analyze("ur5")
    assert (A.rank, len(A.names)) == (22, 24)
    assert _names(A, A.fixed) == ("d3", "d4")
    assert A.combinations == ("d2 + d3 + d4",)
    B = _analyze("ur5", base=True, tool=True)
    assert (B.rank, len(B.names)) == (28, 36)
    assert _names(B, B.fixed) == ("d3", "d4", "base_z", "base_rz", "tool_x", "tool_z", "tool_rx", "tool_rz")
    P = _analyze("ur5", position_only=True)
    assert (P.rank, P.unidentifiable) == (18, ("theta6", "alpha6"))
    assert P.combinations == ("d2 + d3 + d4", "theta5 - 0.01215 a5", "d5 + 82.3 alpha5")


def test_generic_and_mdh_arms():
    """Controls: a random SDH arm has no parallel axes (full rank 24); the Panda is MDH, where
    joint 1's a and alpha act before q1, so a base twist absorbs four parameters
    (theta1, d1, a1, alpha1): 28 + 6 - 4 = rank 30 of 34."""
    robot = jaxcal.Robot(random_dh(np.random.default_rng(3)))
    J = E.identification_jacobian(robot, jnp.asarray(_poses(robot)))
    A = analyze(J, E.param_names(robot))
    assert (A.rank, A.fixed, A.combinations) == (24, (), ())
    P = _analyze("panda", base=True)
    assert (P.rank, len(P.names)) == (30, 34)
    assert P.combinations == ("theta1 + base_rz", "d1 + base_z", "a1 + base_x", "alpha1 + base_rx")


@pytest.mark.parametrize(
    "cfg",
    [
        ("paper-6r", {}),
        ("paper-6r", dict(position_only=True, tool=True)),
        ("puma560", dict(position_only=True, base=True)),
        ("ur5", dict(base=True, tool=True)),
    ],
)
def test_combination_matrix_is_base_least_squares(cfg):
    """Noise-free data J x_true fitted with the base columns only gives C @ x_true."""
    J, names = _jac(cfg[0], **cfg[1])
    A = analyze(J, names)
    Jf = J.reshape(-1, J.shape[-1])
    rng = np.random.default_rng(11)
    is_angle = np.array([n.startswith(("theta", "alpha", "base_r", "tool_r")) for n in names])
    for _ in range(3):
        x = rng.normal(size=len(names)) * np.where(is_angle, 1e-3, 0.1)
        xb = np.linalg.lstsq(Jf[:, list(A.base)], Jf @ x, rcond=None)[0]
        assert_allclose(xb, A.combination_matrix @ x, atol=1e-9, rtol=0)


def test_crlb_matches_monte_carlo():
    """y = J x + e, e ~ N(0, diag(sigma^2)); weighted LS on the base columns is unbiased for C x
    and its covariance is inv(J_b^T W J_b)."""
    J, names = _jac("paper-6r", base=True)
    A = analyze(J, names)
    sig = row_sigmas(J.shape[0], sigma_pos_mm=0.05, sigma_rot_rad=2e-4)
    cov = crlb(J, sig, A)
    nb = len(A.base)
    assert cov.shape == (nb, nb) and np.all(np.linalg.eigvalsh(cov) > 0)
    rng = np.random.default_rng(5)
    Jf = J.reshape(-1, J.shape[-1])
    x = rng.normal(size=len(names)) * 0.01
    Jw = Jf[:, list(A.base)] / sig[:, None]
    draws = 8000
    Y = (Jf @ x)[None, :] + rng.normal(size=(draws, len(sig))) * sig
    est = np.linalg.lstsq(Jw, (Y / sig).T, rcond=None)[0].T
    emp = np.cov(est, rowvar=False)
    assert_allclose(np.diag(emp), np.diag(cov), rtol=0.1)
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(est.mean(0) - A.combination_matrix @ x) < 5 * sd / np.sqrt(draws))
    corr_err = emp / np.outer(sd, sd) - cov / np.outer(sd, sd)
    assert np.abs(corr_err).max() < 0.1


def test_crlb_sigma_forms_agree():
    """Per-row flat sigmas, a per-pose pattern, and (K, r, m) or (rows, m) J give one answer."""
    J, names = _jac("ur5")
    A = analyze(J, names)
    flat = row_sigmas(J.shape[0], sigma_pos_mm=0.1, sigma_rot_rad=1e-3)
    assert flat.shape == (J.shape[0] * 6,)
    assert_array_equal(flat[:6], [0.1, 0.1, 0.1, 1e-3, 1e-3, 1e-3])
    ref = crlb(J, flat, A)
    pattern = [0.1, 0.1, 0.1, 1e-3, 1e-3, 1e-3]
    for Jx, s in [(J, pattern), (J.reshape(-1, 24), pattern), (J.reshape(-1, 24), flat), (J, flat.reshape(-1, 6))]:
        assert_allclose(crlb(Jx, s, A), ref, rtol=1e-10)
    # a scalar sigma scales the covariance by sigma^2; against the normal equations directly
    Jb = J.reshape(-1, 24)[:, list(A.base)]
    assert_allclose(crlb(J, 0.2, A), 0.04 * np.linalg.inv(Jb.T @ Jb), rtol=1e-6)
    assert row_sigmas(4, position_only=True, sigma_pos_mm=0.1).shape == (12,)
    with pytest.raises(DataError):
        crlb(J, np.ones(5), A)
    with pytest.raises(DataError):
        row_sigmas(3, sigma_pos_mm=0.1)


def test_deterministic_and_row_order_free():
    J, names = _jac("ur5", base=True, tool=True)
    A, B = analyze(J, names), analyze(J, names)
    for f in ("names", "rank", "base", "fixed", "unidentifiable", "combinations", "condition_number", "indices"):
        assert getattr(A, f) == getattr(B, f)
    assert_array_equal(A.combination_matrix, B.combination_matrix)
    assert_array_equal(A.singular_values, B.singular_values)
    Jf = J.reshape(-1, J.shape[-1])
    P = analyze(Jf[np.random.default_rng(2).permutation(Jf.shape[0])], names)
    assert (P.rank, P.base, P.fixed, P.combinations) == (A.rank, A.base, A.fixed, A.combinations)
    assert_allclose(P.combination_matrix, A.combination_matrix, atol=1e-9)


@pytest.mark.parametrize("cfg", [("paper-6r", {}), ("puma560", dict(position_only=True, tool=True))])
def test_observability_indices_by_hand(cfg):
    J, names = _jac(cfg[0], **cfg[1])
    A = analyze(J, names)
    Jf = J.reshape(-1, J.shape[-1])[:, list(A.base)]
    s = np.linalg.svd(Jf / np.sqrt((Jf**2).sum(0)), compute_uv=False)
    r, rows = len(s), Jf.shape[0]
    hand = {
        "O1": np.prod(s) ** (1 / r) / np.sqrt(rows),
        "O2": s.min() / s.max(),
        "O3": s.min(),
        "O4": s.min() ** 2 / s.max(),
        "O5": 1 / np.sum(1 / s),
    }
    assert A.indices.keys() == hand.keys()
    for k in hand:
        assert_allclose(A.indices[k], hand[k], rtol=1e-9)
    assert_allclose(A.condition_number, s.max() / s.min(), rtol=1e-9)


def test_report_and_col_scale():
    A = _analyze("paper-6r", position_only=True, tool=True)
    text = A.report()
    assert "rank 18 of 30" in text and "d2 + d3" in text and "tool_rx" in text
    assert "condition number" in text and all(f"O{i} =" in text for i in range(1, 6))
    # explicit typical magnitudes (0.1 mm, 1 mrad) instead of unit-norm columns: same structure
    J, names = _jac("paper-6r", position_only=True, tool=True)
    is_angle = np.array([n.startswith(("theta", "alpha", "tool_r")) for n in names])
    S = analyze(J, names, col_scale=np.where(is_angle, 1e-3, 0.1))
    assert (S.rank, S.base, S.unidentifiable, S.combinations) == (A.rank, A.base, A.unidentifiable, A.combinations)
    assert_allclose(S.combination_matrix, A.combination_matrix, atol=1e-9)


def test_bad_input_and_borderline_spectrum():
    J, names = _jac("paper-6r")
    with pytest.raises(DataError, match="names"):
        analyze(J, names[:-1])
    bad = J.copy()
    bad[3, 2, 5] = np.nan
    with pytest.raises(DataError, match="non-finite"):
        analyze(bad, names)
    with pytest.raises(DataError):
        analyze(J, names, col_scale=-np.ones(24))
    # singular values straddle the threshold: the full set has rank 2 but no in-order pair
    # passes; the base set is topped up (pivoted QR) to the numerical rank, with a warning
    t = 2e-8
    M = np.array([[1, 1, 1], [0, t, -t]], float)
    with pytest.warns(UserWarning, match="topped up"):
        B = analyze(M, ["p", "q", "r"])
    assert B.rank == len(B.base) == 2 and B.base[0] == 0


def test_a_column_new_only_by_rounding_does_not_take_a_place():
    """b = a + 3.7e-6 c (a right angle written 1.5708 rad turns a shift by that much): rank 2,
    and the base set is {a, c}, not {a, b} (which would estimate c through b - a, condition
    ~1e6: the unregularized fit's step is then ~1e6 times the noise)."""
    rng = np.random.default_rng(0)
    a, c = rng.normal(size=(2, 40))
    A = analyze(np.c_[a, a + 3.7e-6 * c, c], ["a", "b", "c"])
    assert A.rank == 2 and A.base_names == ("a", "c") and A.condition_number < 10
    assert A.reasons()["b"].startswith("not separable from a, c")


def test_xarm7_base_set_is_that_of_exact_right_angles(tmp_path):
    """The xArm7 URDF writes its +-pi/2 origins as 1.5708: its base set is the one of exact
    right angles, as well conditioned (the rounding once made it keep y2, y4, y6 in place of
    z2, z4, z6, condition ~1e6)."""
    from pathlib import Path

    from jaxcal.calibration import identify

    text = (Path(__file__).resolve().parent / "data" / "urdf" / "xarm7.urdf").read_text()
    assert "1.5708" in text
    (tmp_path / "exact.urdf").write_text(text.replace("1.5708", repr(np.pi / 2)))
    out = []
    for path in (tmp_path / "exact.urdf", Path(__file__).resolve().parent / "data" / "urdf" / "xarm7.urdf"):
        robot = jaxcal.load_robot(path, base_link="link_base")
        out.append(identify(robot, _poses(robot, 60), n_points=1))
    assert out[1].base_names == out[0].base_names and out[1].rank == out[0].rank
    assert out[1].condition_number < 2 * out[0].condition_number < 100


def test_base_covariance_on_a_stack(rng):
    """Stacked pose sets at once, against inv(Jb^T Jb) set by set; a zero column names its set."""
    from jaxcal.identifiability import base_covariance

    Jb = rng.normal(size=(3, 40, 5)) * np.array([1.0, 1e3, 1e-3, 10.0, 1.0])
    got = base_covariance(Jb)
    for k in range(3):
        assert_allclose(got[k], np.linalg.inv(Jb[k].T @ Jb[k]), rtol=1e-9)
    Jb[1, :, 2] = 0.0
    with pytest.raises(DataError, match="zero on pose set 1"):
        base_covariance(Jb)
