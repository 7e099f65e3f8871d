"""The paper's matrices transcribed exactly as printed (typos included), for the errata tests.

Each function returns a 4x4 NumPy matrix. Do not "fix" these: they are the evidence.
"""

import numpy as np


def sdh_dA(theta, d, a, alpha):
    """Eq. (4), dA/d(theta, d, a, alpha), as printed."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    dth = [[-st, -ca * ct, sa * ct, -a * st], [ct, -ca * st, sa * st, a * ct], [0, 0, 0, 0], [0, 0, 0, 0]]
    dd = [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0]]
    da = [[0, 0, 0, ct], [0, 0, 0, st], [0, 0, 0, 0], [0, 0, 0, 0]]
    dal = [[0, st * sa, st * ca, 0], [0, -ct * sa, -ct * ca, 0], [0, ca, -sa, 0], [0, 0, 0, 0]]
    return [np.array(m, float) for m in (dth, dd, da, dal)]


def sdh_omega_parts(theta, d, a, alpha):
    """Eq. (5), Omega_theta, Omega_d, Omega_a, Omega_alpha, as printed."""
    ca, sa = np.cos(alpha), np.sin(alpha)
    om_th = [[0, -ca, sa, 0], [ca, 0, 0, a * ca], [-sa, 0, 0, -a * sa], [0, 0, 0, 0]]
    om_d = [[0, 0, 0, 0], [0, 0, 0, sa], [0, 0, 0, ca], [0, 0, 0, 0]]
    om_a = [[0, 0, 0, 1], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]]
    om_al = [[0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 0]]
    return [np.array(m, float) for m in (om_th, om_d, om_a, om_al)]


def sdh_omega_combined(theta, d, a, alpha, dth, dd, da, dal):
    """Eq. (5), the combined Omega_i, as printed."""
    ca, sa = np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [0, -ca * dth, sa * dth, da],
            [ca * dth, 0, dal, a * ca * dth + sa * dd],
            [-sa * dth, -dal, 0, -a * sa * dth + ca * dd],
            [0, 0, 0, 0],
        ],
        float,
    )


def mdh_dA(theta, d, a, alpha):
    """Eq. (6), the MDH dA/d(theta, d, a, alpha), as printed."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    dth = [[-st, -ca * ct, 0, 0], [ca * ct, -ca * st, 0, 0], [sa * st, -sa * ct, 0, 0], [0, 0, 0, 0]]
    dd = [[0, 0, 0, 0], [0, 0, 0, -sa], [0, 0, 0, ca], [0, 0, 0, 0]]
    da = [[0, 0, 0, 1], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]]
    dal = [[0, 0, 0, 0], [-st * sa, -ct * sa, -ca, -d * ca], [st * ca, ct * ca, -sa, -d * sa], [0, 0, 0, 0]]
    return [np.array(m, float) for m in (dth, dd, da, dal)]


def mdh_omega_combined(theta, d, a, alpha, dth, dd, da, dal):
    """Eq. (7), the MDH combined Omega_i, as printed."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [0, -ca * dth, sa * dth, -d * st * dal + ct * da],
            [dth, 0, -ct * dal, -d * ct * dal - st * da],
            [st * dth, ct * dal, 0, dd],
            [0, 0, 0, 0],
        ],
        float,
    )


def eq13_w6(F, a, dth, dd, da, dal):
    """Eq. (13), W_6 = T_6 Omega_6 T_6^{-1} for alpha_6 = 0 in the entries f_ij of T_6, the
    simplified (second) line of each entry as printed; the lower triangle by eq. (12)."""
    f = lambda i, j: F[i - 1][j - 1]  # noqa: E731
    w12 = -f(3, 3) * dth - f(3, 1) * dal
    w13 = f(2, 3) * dth + f(2, 1) * dal
    w23 = -f(1, 3) * dth - f(1, 1) * dal
    w14 = (f(2, 4) * f(3, 3) + f(3, 4) * f(2, 3) + f(1, 2) * a) * dth + (f(2, 4) * f(3, 1) - f(3, 4) * f(2, 1)) * dal
    w14 += f(1, 3) * dd + f(1, 1) * da
    w24 = (-f(1, 4) * f(3, 3) + f(3, 4) * f(1, 3) + f(2, 2) * a) * dth + (-f(1, 4) * f(3, 1) - f(3, 4) * f(1, 1)) * dal
    w24 += f(2, 3) * dd + f(2, 1) * da
    w34 = (f(1, 4) * f(2, 3) - f(2, 4) * f(1, 3) + f(3, 2) * a) * dth + (f(1, 4) * f(2, 1) + f(2, 4) * f(1, 1)) * dal
    w34 += f(3, 3) * dd + f(3, 1) * da
    return np.array([[0, w12, w13, w14], [-w12, 0, w23, w24], [-w13, -w23, 0, w34], [0, 0, 0, 0]], float)
