r"""How well a calibrated model predicts positions: the parameter covariance propagated through
the model.

At joint values ``q`` a measured point's (or, for pose data, the tool origin's) predicted
position ``p(x, q)`` has, to first order, the covariance ``J Σ J^T`` with ``J = dp/dx`` the rows
of the identification Jacobian (:func:`jaxcal.model.jacobian`) and ``Σ`` the covariance of the
fitted parameters. Its square-rooted trace is the expected RMS distance (mm) between the model's
prediction and the true position: the model's share of a held-out error; the measurement noise
(``sqrt(3) sigma_pos`` per point) comes on top.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from jaxtyping import Float

from ..model import Layout, Model
from . import _core as core


def position_std(model: Model, layout: Layout, covariance, q: Float[np.ndarray, "K n"]) -> np.ndarray:
    """``(K, M)`` predicted standard deviation (mm, the RMS distance: ``sqrt(trace(J Σ J^T))``)
    of the position of each measured point (``M = 1`` for pose data: the tool origin) at the
    joint values ``q (K, n)``, from the ``covariance`` of the parameters of ``layout``. A camera
    model's unknowns describe the sensor, not the robot, and are left out."""
    lay = dataclasses.replace(layout, camera="none")
    m = lay.size
    cov = np.asarray(covariance)[:m, :m]
    pts = np.asarray(model.points) if layout.n_points else None
    J = core.analyse(Model(model.robot.stripped(), pts), lay, np.asarray(q, np.float64))[0]
    M = max(layout.n_points, 1)
    Jp = J[:, : 3 * M].reshape(J.shape[0], M, 3, m)
    var = np.einsum("kmri,ij,kmrj->km", Jp, cov, Jp)
    return np.sqrt(np.clip(var, 0.0, None))
