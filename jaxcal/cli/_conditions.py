"""The conditions ``jaxcal design`` and ``jaxcal montecarlo`` share: a box and a camera's view
cone the measured points must stay in, and pose files (validation poses, candidates, designs),
parsed once so both commands read them alike."""

from __future__ import annotations

import math

import numpy as np

REGION_HELP = (
    "box the measured point(s) must stay in: xmin,ymin,zmin,xmax,ymax,zmax (mm, the frame the robot file's "
    "base is given in: its measurement frame)"
)
VIEW_HELP = (
    "a camera's view cone the measured point(s) must stay in: X,Y,Z,DX,DY,DZ,HALF_ANGLE[,NEAR,FAR] "
    "(camera position and viewing direction in mm, the frame the robot file's base is given in; half-angle "
    "in deg; range along the axis in mm)"
)
SPREAD_HELP = "smallest joint-space distance between two poses (rad)"


def numbers(text: str, count: int | tuple[int, ...], option: str) -> list[float]:
    """``count`` comma-separated numbers of ``option``, or a DataError naming it."""
    from ..errors import DataError

    counts = (count,) if isinstance(count, int) else count
    try:
        out = [float(t) for t in text.split(",")]
    except ValueError:
        out = []
    if len(out) not in counts or not all(math.isfinite(v) for v in out):
        said = " or ".join(map(str, counts))
        raise DataError(f"{option} must be {said} comma-separated numbers, all finite, got {text!r}", option=option)
    return out


def region_arg(text: str | None):
    """``--region`` as ``(lower xyz, upper xyz)`` (None if not given)."""
    if text is None:
        return None
    v = numbers(text, 6, "region")
    return v[:3], v[3:]


def view_arg(text: str | None):
    """``--view`` as ``(origin, axis, half_angle rad[, near, far])`` (None if not given)."""
    if text is None:
        return None
    v = numbers(text, (7, 9), "view")
    return v[:3], v[3:6], np.radians(v[6]), *v[7:]


def read_poses_for(path, robot, option: str):
    """The pose file given to ``option`` (None if not given); its errors are said of the option."""
    from ..design import read_poses
    from ..errors import DataError

    if path is None:
        return None
    try:
        return read_poses(path, robot)
    except DataError as e:
        raise DataError(f"{option}: {e}", option=option) from None
