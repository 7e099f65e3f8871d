# %% [markdown]
# # The paper's derivations, checked with autodiff
#
# Wang, Liu & Liu (2022) derive the standard-DH (SDH) link transform (eq. 1), its partial
# derivatives (eq. 4), the error operators $\Omega = A^{-1}\,\partial A/\partial p$ (eq. 5),
# their MDH counterparts (eq. 6-7) and the differential error model
# $dT\,T^{-1} = \sum_i T_i \Omega_i T_i^{-1}$ (eq. 10). jaxcal implements each one from the
# closed form; here every one is compared with `jax.jacfwd` of the link transform, and the
# paper's printed versions (typos included) are compared too. The errata are listed in
# `docs/errata.md`.
#
# Open with `jupytext --to notebook notebooks/01_derivations_autodiff.py` or run as a script.

# %%
import os

import jax
import jax.numpy as jnp
import numpy as np

import jaxcal
from jaxcal import derivatives as D
from jaxcal import error_model as E
from jaxcal import kinematics as K

SMALL = os.environ.get("JAXCAL_NB_SMALL") == "1"
N = 200 if SMALL else 5000
rng = np.random.default_rng(0)
P = np.c_[rng.uniform(-7, 7, N), rng.uniform(-1e3, 1e3, N), rng.uniform(-1e3, 1e3, N), rng.uniform(-7, 7, N)]
P[:40, 3] = np.tile([0.0, np.pi / 2, -np.pi / 2, np.pi], 10)  # the paper's special alphas

# %% [markdown]
# ## Eq. (1) and (4): the SDH link and its partial derivatives
# `jacfwd` puts the differentiated axis last; we move it first to match `sdh_partials`'s
# `(..., k, 4, 4)` layout.

# %%
def autodiff_partials(conv, P):
    f = lambda p: jnp.moveaxis(jax.jacfwd(lambda x: K.LINKS[conv](*x))(p), -1, 0)
    return np.asarray(jax.vmap(f)(jnp.asarray(P)))


ad_sdh = autodiff_partials("sdh", P)
print("eq. 4  max |analytic - jacfwd| =", np.abs(np.asarray(D.sdh_partials(*P.T)) - ad_sdh).max())

# %% [markdown]
# ## Eq. (5): SDH error operators, and the erratum in the combined $\Omega_i$
# The four separate operators are printed correctly. The combined matrix has the signs of its
# $\Delta\alpha$ entries (2,3) and (3,2) swapped (erratum E1).

# %%
A = np.asarray(K.sdh_link(*P.T))
om_ad = np.linalg.solve(A[:, None], ad_sdh)
print("eq. 5  max |analytic - A^-1 jacfwd| =", np.abs(np.asarray(D.sdh_omegas(*P.T)) - om_ad).max())

th, d, a, al = 0.7, 123.0, 321.0, -0.4
dth, dd, da, dal = 1e-3, 2e-2, -3e-2, 4e-3
ca, sa = np.cos(al), np.sin(al)
printed = np.array([[0, -ca * dth, sa * dth, da], [ca * dth, 0, dal, a * ca * dth + sa * dd],
                    [-sa * dth, -dal, 0, -a * sa * dth + ca * dd], [0, 0, 0, 0]])
truth = np.einsum("kij,k->ij", np.asarray(D.sdh_omegas(th, d, a, al)), [dth, dd, da, dal])
print("entries where the printed combined Omega_i is wrong (1-based):",
      [(int(i) + 1, int(j) + 1) for i, j in zip(*np.nonzero(np.abs(printed - truth) > 1e-12))])

# %% [markdown]
# ## Eq. (6)-(7): MDH
# Printed `dA/dtheta` has three wrong entries (E2), the combined MDH $\Omega_i$ three more (E3).

# %%
ad_mdh = autodiff_partials("mdh", P)
Am = np.asarray(K.mdh_link(*P.T))
print("eq. 6  max |analytic - jacfwd| =", np.abs(np.asarray(D.mdh_partials(*P.T)) - ad_mdh).max())
print("eq. 7  max |analytic - A^-1 jacfwd| =",
      np.abs(np.asarray(D.mdh_omegas(*P.T)) - np.linalg.solve(Am[:, None], ad_mdh)).max())
ct, st = np.cos(th), np.sin(th)
printed_dth = np.array([[-st, -ca * ct, 0, 0], [ca * ct, -ca * st, 0, 0], [sa * st, -sa * ct, 0, 0], [0, 0, 0, 0]])
true_dth = np.asarray(D.mdh_partials(th, d, a, al))[0]
print("printed MDH dA/dtheta wrong at:",
      [(int(i) + 1, int(j) + 1) for i, j in zip(*np.nonzero(np.abs(printed_dth - true_dth) > 1e-12))])

# %% [markdown]
# ## Does $\Omega$ depend on the joint angle?
# The paper: SDH's does not, MDH's does. Autodiff $\partial\Omega/\partial\theta$ per parameter
# (theta, d, a, alpha), for right- ($A^{-1}dA$) and left- ($dA\,A^{-1}$) multiplied errors:

# %%
def theta_dependence(fn):
    g = jax.vmap(lambda p: jax.jacfwd(lambda t: fn(t, p[1], p[2], p[3]))(p[0]))
    return np.abs(np.asarray(g(jnp.asarray(P[40:240])))).max(axis=(0, 2, 3))


for name, fn in [("SDH right", D.sdh_omegas), ("MDH right", D.mdh_omegas),
                 ("SDH left", D.sdh_left_omegas), ("MDH left", D.mdh_left_omegas)]:
    print(f"{name:10s} max |dOmega/dtheta| for (theta, d, a, alpha):", np.round(theta_dependence(fn), 6))

# %% [markdown]
# ## Eq. (10): the error model and the identification Jacobian
# The literal 4x4 sum, its adjoint form, and `jacfwd` of the exact nonlinear pose error agree;
# the first-order model's remainder shrinks quadratically.

# %%
robot = jaxcal.preset("paper-6r")
Q = jnp.asarray(rng.uniform(-2, 2, (20, 6)))
J = E.identification_jacobian(robot, Q)
true_err = lambda x, q: E.pose_error(jaxcal.fk(E.perturb(robot, x), q), jaxcal.fk(robot, q))
J_ad = jax.vmap(lambda q: jax.jacfwd(true_err)(jnp.zeros(24), q))(Q)
print("identification Jacobian vs jacfwd:", float(jnp.abs(J - J_ad).max()))
dx = jnp.asarray(rng.normal(size=24)) * jnp.tile(jnp.array([1e-2, 1.0, 1.0, 1e-2]), 6)
for s in (1e-2, 5e-3, 2.5e-3):
    rem = jax.vmap(lambda q: true_err(s * dx, q))(Q) - J @ (s * dx)
    print(f"scale {s:.4f}: first-order remainder {float(jnp.abs(rem).max()):.3e}")
