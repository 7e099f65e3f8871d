"""The variants timed by ``bench_roofline.py``: the shipped native kernel (both FK layouts), the
pure-JAX fallback and the earlier forms and levers (each a function of the joint angles
``q (K, n)`` for one robot; those in :data:`POSE_LAST` of ``q (n, K)``)."""

from __future__ import annotations

NATIVE = "jaxcal: native kernel"
NATIVE_LAST = "jaxcal: native kernel, pose axis last"
POSE_LAST = {NATIVE_LAST}
"""Variants that take the joint values as ``(n, K)`` and return ``(4, 4, K)`` (``fk_pose_last``)."""
PURE = "pure JAX (the fallback)"
SMALL = 10_000  # poses per call for the second native row: its output stays clear of page faults


def variants(robot):
    import jax
    import jax.numpy as jnp
    import numpy as np
    import jaxcal
    from jaxcal.error_model import identification_jacobian, perturb, pose_error
    from jaxcal.derivatives import OMEGA_TWISTS
    from jaxcal.error_model import twist_to_pose_rows
    from jaxcal.kinematics import LINKS, joint_dh, link_transforms
    from jaxcal.lie import compose

    def frames_before(q):
        A = link_transforms(robot, q)
        T = jnp.broadcast_to(robot.base, A.shape[:-3] + (4, 4))
        frames = []
        for i in range(robot.n_joints):
            T = compose(T, A[..., i, :, :])
            frames.append(T)
        return jnp.stack(frames, -3)

    def fk_before(q):
        return compose(frames_before(q)[..., -1, :, :], robot.tool)

    def jac_before(q):
        frames = frames_before(q)
        p = joint_dh(robot, q)
        local = OMEGA_TWISTS[robot.convention](p[..., 0], p[..., 1], p[..., 2], p[..., 3])
        R, pos = frames[..., None, :3, :3], frames[..., None, :3, 3]
        w_s = (R * local[..., None, 3:]).sum(-1)
        v_s = (R * local[..., None, :3]).sum(-1) + jnp.cross(pos, w_s)
        cols = jnp.concatenate([v_s, w_s], -1)
        cols = jnp.moveaxis(cols.reshape(cols.shape[:-3] + (4 * robot.n_joints, 6)), -1, -2)
        return twist_to_pose_rows(cols, compose(frames[..., -1, :, :], robot.tool)[..., :3, 3])

    def jac_scan_twists(q):
        """The previous shipped Jacobian (commit d42a99f): spatial twists formed inside the
        lax.scan over links as broadcast (4, 3, K) blocks, then pose rows and one transpose."""
        from jaxcal.derivatives import omega_twist_entries
        from jaxcal.kinematics import _dot3, _link_entries, link_inputs, rotate_soa

        def cross_soa(u, v):  # u x v along axis -2, pose axis last
            u0, u1, u2 = u[..., 0, :], u[..., 1, :], u[..., 2, :]
            v0, v1, v2 = v[..., 0, :], v[..., 1, :], v[..., 2, :]
            return jnp.stack([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0], -2)

        c, s, d = link_inputs(robot, q)
        K = c.shape[1]
        top = jnp.concatenate([robot.base[:3, :3].reshape(9), robot.base[:3, 3]])

        def link(S, x):
            R = [[S[3 * r + k] for k in range(3)] for r in range(3)]
            A_R, A_t = _link_entries(robot.convention, *x)
            e = [_dot3(R[r], [A_R[0][k], A_R[1][k], A_R[2][k]]) for r in range(3) for k in range(3)]
            e += [_dot3(R[r], A_t) + S[9 + r] for r in range(3)]
            S = jnp.stack([jnp.broadcast_to(v, (K,)) for v in e])
            o = jnp.ones((K,))
            ent = omega_twist_entries(robot.convention, *x)
            V, W = (jnp.stack([jnp.stack([o * v for v in vw[j]]) for vw in ent])
                    for j in (0, 1))
            Rb, tb = S[:9].reshape(3, 3, K), S[9:]
            w_s = rotate_soa(Rb, W)
            v_s = rotate_soa(Rb, V) + cross_soa(jnp.broadcast_to(tb, w_s.shape), w_s)
            return S, jnp.concatenate([v_s, w_s], 1).reshape(24, K)

        S, tw = jax.lax.scan(link, jnp.broadcast_to(top[:, None], (12, K)), (c, s, d, robot.dh[:, 2], robot.dh[:, 3]))
        tw = tw.reshape(4 * robot.n_joints, 6, K)
        p_e = rotate_soa(S[:9].reshape(3, 3, K), jnp.broadcast_to(robot.tool[:3, 3, None], (3, K))) + S[9:]
        J = jnp.concatenate([tw[:, :3] + cross_soa(tw[:, 3:], jnp.broadcast_to(p_e, tw[:, 3:].shape)), tw[:, 3:]], 1)
        return jnp.transpose(J, (2, 1, 0))

    def fk_scan(q):
        A = LINKS[robot.convention](*jnp.moveaxis(joint_dh(robot, q), -1, 0))  # (K, n, 4, 4)
        T0 = jnp.broadcast_to(robot.base, A.shape[:-3] + (4, 4))
        T, _ = jax.lax.scan(lambda T, Ai: (compose(T, Ai), None), T0, jnp.moveaxis(A, -3, 0))
        return compose(T, robot.tool)

    def fk_soa(q):
        """Batch-major, fully scalarised (SDH): joint angles as (n, K) rows, every entry of the
        running transform a (K,) vector, nothing stacked until the end."""
        assert robot.convention == "sdh"
        dh = np.asarray(robot.dh)
        qT = q.T
        R = [[jnp.float64(robot.base[i, j]) for j in range(3)] for i in range(3)]
        t = [jnp.float64(robot.base[i, 3]) for i in range(3)]
        for i in range(robot.n_joints):
            th0, d, a, al = dh[i]
            ct, st = jnp.cos(qT[i] + th0), jnp.sin(qT[i] + th0)
            ca, sa = np.cos(al), np.sin(al)
            A = [[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0.0, sa, ca, d]]
            t = [R[r][0] * A[0][3] + R[r][1] * A[1][3] + R[r][2] * A[2][3] + t[r] for r in range(3)]
            R = [[R[r][0] * A[0][c] + R[r][1] * A[1][c] + R[r][2] * A[2][c] for c in range(3)] for r in range(3)]
        tool = np.asarray(robot.tool)
        t = [R[r][0] * tool[0, 3] + R[r][1] * tool[1, 3] + R[r][2] * tool[2, 3] + t[r] for r in range(3)]
        R = [[R[r][0] * tool[0, c] + R[r][1] * tool[1, c] + R[r][2] * tool[2, c] for c in range(3)] for r in range(3)]
        K = q.shape[0]
        top = jnp.stack([jnp.stack([jnp.broadcast_to(x, (K,)) for x in R[r] + [t[r]]], -1) for r in range(3)], -2)
        bottom = jnp.broadcast_to(jnp.array([0.0, 0.0, 0.0, 1.0]), (K, 1, 4))
        return jnp.concatenate([top, bottom], -2)

    def chunked(f, size):
        def g(q):
            K = q.shape[0]
            pad = (-K) % size
            qp = jnp.concatenate([q, jnp.zeros((pad, q.shape[1]))]) if pad else q
            out = jax.lax.map(f, qp.reshape(-1, size, q.shape[1]))
            return out.reshape((-1,) + out.shape[2:])[:K]
        return g

    jac = lambda q: identification_jacobian(robot, q)
    m = 4 * robot.n_joints

    def jac_jacfwd(q):
        def err(x, qk):
            return pose_error(jaxcal.fk(perturb(robot, x), qk), jaxcal.fk(robot, qk))
        return jax.vmap(lambda qk: jax.jacfwd(err)(jnp.zeros(m), qk))(q)

    from jaxcal.error_model import _columns_xla
    from jaxcal.kinematics import _chain, _fk_xla
    from jaxcal.lie import make_transform

    def libm_inputs(q):  # link_inputs with XLA's sin/cos (the pure-JAX path before jaxcal.trig)
        qT = q.T
        theta = robot.dh[:, 0:1] + qT * robot.revolute_mask[:, None]
        return jnp.cos(theta), jnp.sin(theta), robot.dh[:, 1:2] + qT * (1.0 - robot.revolute_mask[:, None])

    def fk_libm(q):
        R, t, _ = _chain(robot, libm_inputs(q), frames=False)
        return compose(make_transform(jnp.moveaxis(R, -1, 0), t.T), robot.tool)

    def jac_libm(q):
        import jaxcal.error_model as em
        saved = em.link_inputs
        em.link_inputs = lambda robot_, q_: libm_inputs(q_)
        try:
            return _columns_xla(robot, q, base=False, tool=False, pose_rows=True)
        finally:
            em.link_inputs = saved

    fk = lambda q: jaxcal.fk(robot, q)
    fk_x = lambda q: _fk_xla(robot, q)
    jac_x = lambda q: _columns_xla(robot, q, base=False, tool=False, pose_rows=True)
    return {
        "FK": {NATIVE: fk, NATIVE_LAST: lambda qT: jaxcal.fk_pose_last(robot, qT), PURE: fk_x, "pure JAX, XLA sin/cos (01cbb2a)": fk_libm,
               "before: 4x4 unrolled, fused": fk_before,
               "4x4, lax.scan over links": fk_scan, "SoA, links unrolled": fk_soa,
               "pure JAX chunked 1024 (lax.map)": chunked(fk_x, 1024),
               "pure JAX chunked 8192 (lax.map)": chunked(fk_x, 8192)},
        "Jacobian": {NATIVE: jac, PURE: jac_x, "pure JAX, XLA sin/cos (01cbb2a)": jac_libm,
                     "twists in the scan (d42a99f)": jac_scan_twists,
                     "before: closed form, 4x4": jac_before,
                     "jacfwd through FK": jac_jacfwd,
                     "pure JAX chunked 1024 (lax.map)": chunked(jac_x, 1024),
                     "pure JAX chunked 8192 (lax.map)": chunked(jac_x, 8192)},
    }


