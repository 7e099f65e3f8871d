"""The fused native kernels (jaxcal._native) against the pure-JAX reference they replace:
forward kinematics and the identification Jacobian, both conventions, base/tool columns,
position-only rows, prismatic joints, odd pose counts, leading axes, vmap over robots,
derivatives; and the fallback when the kernel cannot be built or is switched off."""

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from conftest import random_dh, random_transform
from jaxcal import Robot, fk, presets
from jaxcal import _native
from jaxcal.error_model import _columns_xla, identification_jacobian, jacobian_and_fk, n_params, perturb
from jaxcal.kinematics import _fk_pose_last_xla, _fk_xla, fk_pose_last

pytestmark = pytest.mark.skipif(not _native.available(), reason=f"native kernel not in use: {_native.status()[1]}")

ATOL = 1e-9  # mm (positions of order 1e3 mm) and rad; the two differ by rounding only (~1e-13)


def _robot(conv, types, seed):
    rng = np.random.default_rng(seed)
    n = len(types)
    return Robot(random_dh(rng, n), convention=conv, joint_types=types, base=random_transform(rng),
                 tool=random_transform(rng))


ROBOTS = [("sdh", ("R",) * 6, 1), ("mdh", ("R",) * 7, 2), ("sdh", ("R", "P", "R", "R"), 3), ("mdh", ("P", "R", "R"), 4),
          ("sdh", ("R", "P") * 8, 5)]  # the longest chain the kernel takes (MAX_JOINTS)


@pytest.mark.parametrize("conv,types,seed", ROBOTS)
@pytest.mark.parametrize("shape", [(1,), (63,), (65,), (2, 3, 70)])
def test_fk_matches_pure_jax(conv, types, seed, shape):
    robot = _robot(conv, types, seed)
    q = np.random.default_rng(seed + 10).uniform(-3, 3, shape + (robot.n_joints,))
    got = np.asarray(fk(robot, q))
    assert got.shape == shape + (4, 4)
    assert_allclose(got, np.asarray(jax.jit(_fk_xla)(robot, jnp.asarray(q))), rtol=0, atol=ATOL)
    # the pose-last kernel: the same arithmetic per lane, so the same bits
    last = np.asarray(fk_pose_last(robot, np.moveaxis(q, -1, 0)))
    assert last.shape == (4, 4) + shape
    assert_array_equal(np.moveaxis(last, (0, 1), (-2, -1)), got)


@pytest.mark.parametrize("conv,types,seed", ROBOTS)
@pytest.mark.parametrize("base,tool,position_only", [(False, False, False), (True, True, False), (True, False, True),
                                                     (False, True, True)])
def test_jacobian_matches_pure_jax(conv, types, seed, base, tool, position_only):
    robot = _robot(conv, types, seed)
    q = jnp.asarray(np.random.default_rng(seed + 20).uniform(-3, 3, (2, 67, robot.n_joints)))
    J, T = jacobian_and_fk(robot, q, base=base, tool=tool, position_only=position_only)
    J_ref, T_ref = jax.jit(_columns_xla, static_argnames=("base", "tool", "pose_rows", "rows", "with_pose"))(
        robot, q, base=base, tool=tool, pose_rows=True, rows=3 if position_only else 6, with_pose=True)
    assert J.shape == J_ref.shape and T.shape == (2, 67, 4, 4)
    assert_allclose(J, J_ref, rtol=0, atol=ATOL)
    assert_allclose(T, T_ref, rtol=0, atol=ATOL)
    assert_allclose(identification_jacobian(robot, q, base=base, tool=tool, position_only=position_only), J_ref,
                    rtol=0, atol=ATOL)


def test_large_outputs_match_pure_jax():
    """Outputs of several MiB: the kernel advises huge pages for them (``advise_huge``); values
    must not change. 70,000 poses: J is 77 MB, T 9 MB, FK 9 MB, all beyond one 2 MiB page."""
    robot = _robot("sdh", ("R",) * 6, 5)
    q = jnp.asarray(np.random.default_rng(25).uniform(-3, 3, (70_000, 6)))
    J, T = jacobian_and_fk(robot, q)
    assert J.nbytes > 8 * 2**20 and T.nbytes > 8 * 2**20
    sl = np.s_[::97]  # the reference on a subset keeps the test fast
    J_ref, T_ref = jax.jit(_columns_xla, static_argnames=("base", "tool", "pose_rows", "rows", "with_pose"))(
        robot, q[sl], base=False, tool=False, pose_rows=True, rows=6, with_pose=True)
    assert_allclose(np.asarray(J)[sl], J_ref, rtol=0, atol=ATOL)
    assert_allclose(np.asarray(T)[sl], T_ref, rtol=0, atol=ATOL)
    assert_allclose(np.asarray(fk(robot, q))[sl], T_ref, rtol=0, atol=ATOL)


def _perturbed(robot, key):
    m = n_params(robot, base=True, tool=True)
    return perturb(robot, 1e-2 * jax.random.normal(key, (m,)), base=True, tool=True)


def test_vmap_over_robots_and_pose_sets():
    robot = presets.preset("panda")
    robots = jax.vmap(lambda k: _perturbed(robot, k))(jax.random.split(jax.random.key(0), 5))
    q = jnp.asarray(np.random.default_rng(5).uniform(-2, 2, (5, 40, 7)))
    in_axes = (eqx_axes(robots), 0)
    for f, ref in ((fk, _fk_xla),
                   (lambda r, q: jacobian_and_fk(r, q, tool=True)[0],
                    lambda r, q: _columns_xla(r, q, base=False, tool=True, pose_rows=True))):
        got = jax.vmap(f, in_axes=in_axes)(robots, q)          # robots and pose sets batched
        want = jax.vmap(ref, in_axes=in_axes)(robots, q)
        assert_allclose(got, want, rtol=0, atol=ATOL)
        shared = jax.vmap(f, in_axes=(in_axes[0], None))(robots, q[0])  # one pose set, five robots
        assert_allclose(shared, jax.vmap(ref, in_axes=(in_axes[0], None))(robots, q[0]), rtol=0, atol=ATOL)
        one_robot = jax.vmap(f, in_axes=(None, 0))(robot, q)   # one robot, five pose sets
        assert_allclose(one_robot, jax.vmap(ref, in_axes=(None, 0))(robot, q), rtol=0, atol=ATOL)
    # the kernel is what ran (a fallback to pure JAX would pass the comparisons above too)
    assert "jaxcal_fk" in jax.jit(jax.vmap(fk, in_axes=in_axes)).lower(robots, q).as_text()
    assert "jaxcal_jac" in jax.jit(jax.vmap(lambda r, q: jacobian_and_fk(r, q)[0], in_axes=in_axes)).lower(
        robots, q).as_text()
    qT = jnp.moveaxis(q, -1, 1)  # (5 sets, 7 joints, 40 poses)
    got = jax.vmap(fk_pose_last, in_axes=in_axes)(robots, qT)
    assert got.shape == (5, 4, 4, 40)
    assert_allclose(got, jax.vmap(lambda r, x: _fk_pose_last_xla(r, x), in_axes=in_axes)(robots, qT), rtol=0, atol=ATOL)
    assert_allclose(jnp.moveaxis(got, -1, 1), jax.vmap(fk, in_axes=in_axes)(robots, q), rtol=0, atol=ATOL)
    assert "jaxcal_fk_pose_last" in jax.jit(jax.vmap(fk_pose_last, in_axes=in_axes)).lower(robots, qT).as_text()
    nested = jax.vmap(jax.vmap(fk, in_axes=(None, 0)), in_axes=(in_axes[0], None))(robots, q)  # (5 robots, 5 sets)
    assert nested.shape == (5, 5, 40, 4, 4)
    assert_allclose(nested[3, 2], _fk_xla(jax.tree.map(lambda x: x[3], robots), q[2]), rtol=0, atol=ATOL)


def eqx_axes(robots):
    """vmap axes for a batched Robot: 0 on its arrays."""
    return jax.tree.map(lambda _: 0, robots)


def test_derivatives_go_through_the_reference():
    robot = presets.preset("puma560")
    q = jnp.asarray(np.random.default_rng(6).uniform(-2, 2, (4, 6)))
    x0 = jnp.asarray(np.random.default_rng(7).normal(size=n_params(robot, tool=True))) * 1e-2

    def pos(x, q, f):
        return f(perturb(robot, x, tool=True), q)[..., :3, 3]

    def pos_last(x, q):
        return jnp.moveaxis(fk_pose_last(perturb(robot, x, tool=True), q.T)[:3, 3], 0, -1)

    for argnum in (0, 1):
        got = jax.jacfwd(pos, argnums=argnum)(x0, q, fk)
        want = jax.jacfwd(pos, argnums=argnum)(x0, q, _fk_xla)
        assert_allclose(got, want, rtol=0, atol=1e-9)
        assert_allclose(jax.jacfwd(pos_last, argnums=argnum)(x0, q), want, rtol=0, atol=1e-9)
    g = jax.grad(lambda x: jnp.sum(jacobian_and_fk(perturb(robot, x), q)[0] ** 2))(x0[:24])
    g_ref = jax.grad(lambda x: jnp.sum(_columns_xla(perturb(robot, x), q, base=False, tool=False,
                                                    pose_rows=True) ** 2))(x0[:24])
    assert_allclose(g, g_ref, rtol=1e-9, atol=1e-9)


def test_long_chain_uses_pure_jax():
    rng = np.random.default_rng(7)
    robot = Robot(random_dh(rng, _native.MAX_JOINTS + 1), convention="sdh")
    q = rng.uniform(-1, 1, (3, robot.n_joints))
    assert not _native.usable(robot)
    assert_allclose(fk(robot, q), jax.jit(_fk_xla)(robot, jnp.asarray(q)), rtol=0, atol=0)


def _run(env_extra, tmp_path):
    code = textwrap.dedent("""
        import numpy as np, jaxcal
        ok, why = jaxcal.native_status()
        T = jaxcal.fk(jaxcal.preset("paper-6r"), np.full((2, 6), 0.3))
        TL = jaxcal.fk_pose_last(jaxcal.preset("paper-6r"), np.full((6, 2), 0.3))
        assert abs(float(TL[0, 3, 1]) - float(T[1, 0, 3])) < 1e-9
        print(ok, "|", why, "|", repr(float(T[0, 0, 3])))
    """)
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path), **env_extra)
    p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    return p.stdout.strip().splitlines()[-1].split(" | ")


def test_fallback_when_switched_off_or_not_buildable(tmp_path):
    want = float(fk(presets.preset("paper-6r"), np.full((2, 6), 0.3))[0, 0, 3])
    ok, why, x = _run({"JAXCAL_NATIVE": "0"}, tmp_path)
    assert ok == "False" and "JAXCAL_NATIVE=0" in why and abs(float(x) - want) < ATOL
    ok, why, x = _run({"CXX": "false"}, tmp_path)  # a "compiler" that always fails, empty cache
    assert ok == "False" and "compiling the native kernel with false failed" in why and abs(float(x) - want) < ATOL
    assert not list(tmp_path.rglob("*.so"))


def test_jaxcal_verify_checks_the_kernel():
    from jaxcal.verify import check_all

    rows = check_all(60, 0)
    native = [r for r in rows if r[0].startswith("native FK kernel")]
    assert len(native) == len(presets.PRESETS)
    assert all(err <= tol for _, err, tol in rows), [r for r in rows if r[1] > r[2]]


def _np_sdh_fk(robot, q):
    """Standard-DH FK in NumPy with libm's sin/cos, one pose at a time (independent reference)."""
    out = []
    for qk in q:
        T = np.asarray(robot.base)
        for (th0, d0, a, al), qj, t in zip(np.asarray(robot.dh), qk, robot.joint_types):
            th, d = (th0 + qj, d0) if t == "R" else (th0, d0 + qj)
            ct, st, ca, sa = np.cos(th), np.sin(th), np.cos(al), np.sin(al)
            T = T @ np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                              [0, sa, ca, d], [0, 0, 0, 1]])
        out.append(T @ np.asarray(robot.tool))
    return np.array(out)


def test_fk_all_quadrants_over_the_domain():
    """The kernel's sincos takes the quadrant n mod 4 in floating point (vectorised on AVX2 as on
    AVX-512): every quadrant, angles on the quadrant boundaries k pi/4 and across the whole
    accepted range ±DOMAIN rad, against NumPy's sin/cos."""
    from jaxcal.trig import DOMAIN
    robot = _robot("sdh", ("R",) * 6, 7)
    rng = np.random.default_rng(17)
    ks = np.arange(-40, 41)  # k pi/4: every quadrant and its boundaries, both signs
    q = np.concatenate([(np.resize(ks, (len(ks), 6)) + np.arange(6)) * np.pi / 4,
                        rng.uniform(-DOMAIN, DOMAIN, (60, 6)), np.full((1, 6), DOMAIN), np.full((1, 6), -DOMAIN)])
    robot = Robot(robot.dh.at[:, 0].set(0.0), convention="sdh", joint_types=robot.joint_types,
                  base=robot.base, tool=robot.tool)  # theta = q exactly (no offset added)
    assert_allclose(np.asarray(fk(robot, q)), _np_sdh_fk(robot, q), rtol=0, atol=ATOL)


def test_kernel_sincos_matches_numpy():
    """The kernel's own sin/cos (a table of the multiples of pi/8 with AVX-512, jaxcal.trig's
    polynomials otherwise) to jaxcal.trig's bound, 2.3e-16: with one joint, a = 1 and no base or
    tool, the end pose's first column is exactly (cos q, sin q, 0). Every pi/16 boundary, both
    signs, the whole accepted range, and values small enough that sin q = q."""
    from jaxcal.trig import DOMAIN
    robot = Robot(np.array([[0.0, 0.0, 1.0, 0.0]]), convention="sdh", joint_types=("R",))
    k = np.arange(-3000, 3001)
    eps = np.array([-1e-9, -2.2e-16, 0.0, 2.2e-16, 1e-9])
    x = np.concatenate([(k[:, None] * np.pi / 16 + eps).ravel(), np.random.default_rng(3).uniform(-1, 1, 20_000),
                        np.random.default_rng(4).uniform(-DOMAIN, DOMAIN, 50_000), [DOMAIN, -DOMAIN],
                        [0.0, 1e-300, -1e-300]])
    for T in (np.asarray(fk(robot, x[:, None])), np.moveaxis(np.asarray(fk_pose_last(robot, x[None])), -1, 0)):
        assert np.abs(T[:, 0, 0] - np.cos(x)).max() <= 2.3e-16
        assert np.abs(T[:, 1, 0] - np.sin(x)).max() <= 2.3e-16
        assert np.array_equal(T[-2:, 1, 0], x[-2:]) and np.all(T[-3:, 0, 0] == 1.0)


@pytest.mark.skipif("avx512f" not in open("/proc/cpuinfo").read() if os.path.exists("/proc/cpuinfo") else True,
                    reason="the default build already is the path without AVX-512")
def test_build_without_avx512_matches(tmp_path):
    """The kernel's paths for CPUs without AVX-512 (4 lanes, jaxcal.trig's sincos, 4 x 4 stores),
    built here with JAXCAL_NATIVE_FLAGS=-mno-avx512f into an empty cache, run on one thread
    (JAXCAL_NATIVE_THREADS=1): FK both layouts and the Jacobian against the pure-JAX reference,
    and its sincos to 2.3e-16."""
    code = textwrap.dedent("""
        import sys, numpy as np, jaxcal
        from jaxcal.error_model import jacobian_and_fk
        ok, why = jaxcal.native_status()
        assert ok, why
        d = np.load(sys.argv[1])
        robot = jaxcal.Robot(d["dh"], convention="mdh", joint_types=tuple(d["types"]), base=d["base"], tool=d["tool"])
        J, T = jacobian_and_fk(robot, d["q"], tool=True)
        one = jaxcal.Robot(np.array([[0.0, 0.0, 1.0, 0.0]]), convention="sdh", joint_types=("R",))
        np.savez(sys.argv[2], J=J, T=T, TL=jaxcal.fk_pose_last(robot, d["q"].T), S=jaxcal.fk(one, d["x"][:, None]))
    """)
    rng = np.random.default_rng(31)
    types = ("R", "P", "R", "R", "R", "P", "R")
    robot = Robot(random_dh(rng, 7), convention="mdh", joint_types=types, base=random_transform(rng),
                  tool=random_transform(rng))
    q, x = rng.uniform(-3, 3, (203, 7)), rng.uniform(-1e4, 1e4, 20_000)
    np.savez(tmp_path / "in.npz", dh=robot.dh, types=np.array(types), base=robot.base, tool=robot.tool, q=q, x=x)
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"), JAXCAL_NATIVE_FLAGS="-mno-avx512f",
               JAXCAL_NATIVE_THREADS="1")  # and no worker threads: every block on the calling thread
    p = subprocess.run([sys.executable, "-c", code, str(tmp_path / "in.npz"), str(tmp_path / "out.npz")], env=env,
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    out = np.load(tmp_path / "out.npz")
    J_ref, T_ref = jax.jit(_columns_xla, static_argnames=("base", "tool", "pose_rows", "rows", "with_pose"))(
        robot, jnp.asarray(q), base=False, tool=True, pose_rows=True, rows=6, with_pose=True)
    assert_allclose(out["J"], J_ref, rtol=0, atol=ATOL)
    assert_allclose(out["T"], T_ref, rtol=0, atol=ATOL)
    assert_allclose(np.moveaxis(out["TL"], -1, 0), T_ref, rtol=0, atol=ATOL)
    assert np.abs(out["S"][:, 0, 0] - np.cos(x)).max() <= 2.3e-16
    assert np.abs(out["S"][:, 1, 0] - np.sin(x)).max() <= 2.3e-16


def test_concurrent_calls_from_threads():
    """Calls from several Python threads at once (each publishes a job to the kernel's worker
    pool; a job may get the workers or run on its caller alone): every result is the one the same
    call gives alone, and the pose-last and Jacobian kernels share the pool too."""
    from concurrent.futures import ThreadPoolExecutor
    robot = _robot("sdh", ("R", "P", "R", "R", "R", "R"), 8)
    qs = [np.random.default_rng(40 + i).uniform(-3, 3, (3000 + 61 * i, 6)) for i in range(8)]
    fk_j = jax.jit(lambda q: fk(robot, q))
    last_j = jax.jit(lambda q: fk_pose_last(robot, q.T))
    jac_j = jax.jit(lambda q: jacobian_and_fk(robot, q)[0])
    fns = (fk_j, last_j, jac_j)
    want = [[np.asarray(f(q)) for f in fns] for q in qs]

    def work(i):
        return [[np.asarray(f(qs[i])) for f in fns] for _ in range(5)]

    with ThreadPoolExecutor(4) as ex:
        for i, results in enumerate(ex.map(work, range(len(qs)))):
            for got in results:
                for g, w in zip(got, want[i]):
                    assert_array_equal(g, w)
