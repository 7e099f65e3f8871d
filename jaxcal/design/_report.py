"""Design for the calibration that will really run: the parameter set a previous ``jaxcal
calibrate --json`` chose, read from its report, as options of :func:`design_problem`."""

from __future__ import annotations

import json
from pathlib import Path

from ..errors import DataError
from ..robot import Robot

NOT_KINEMATIC = ("base_", "tool_", "point", "compliance")
"""Prefixes of a report's parameters that are not the robot's kinematic ones."""


def _loaded(report) -> tuple[dict, str]:
    """The report as a dict (read from a path) and how to name it in a message."""
    where = "params_from"
    if isinstance(report, (str, Path)):
        where = f"params_from: {report}"
        try:
            report = json.loads(Path(report).read_text())
        except OSError as e:
            raise DataError(f"{where}: cannot read it ({e.strerror})", option="params_from") from None
        except ValueError as e:
            raise DataError(f"{where}: not JSON ({e})", option="params_from") from None
    if not isinstance(report, dict):
        raise DataError(f"{where}: expected a calibration report (a JSON object)", option="params_from")
    return report, where


def report_points(report) -> int:
    """How many points the report's calibration measured by position alone (0: full poses), so a
    design measures what that calibration did; :class:`jaxcal.DataError` as :func:`report_options`."""
    report = _loaded(report)[0]
    if not report.get("position_only"):
        return 0
    points = report.get("points")
    return int(points) if isinstance(points, int) and not isinstance(points, bool) and points >= 1 else 1


def report_options(report, robot: Robot) -> dict:
    """The options of the calibration a ``jaxcal calibrate --json`` report (a path or the loaded
    dict) describes: ``params``, the estimated kinematic parameters by name (``"frames"`` when
    none was), and ``estimate_base``, ``estimate_tool``, ``compliance`` (``"yes"``/``"no"``) and
    ``ridge_mm`` (the chosen set's prior) where the report says.

    The names come from the report's ``estimated_dh`` list (else the kinematic names among its
    ``parameters``). Raises :class:`jaxcal.DataError` (option ``params_from``) for a file that is
    not such a report, or names ``robot`` does not have."""
    report, where = _loaded(report)
    if "estimated_dh" in report:
        names = report["estimated_dh"]
    elif isinstance(report.get("parameters"), dict):
        cams = set(report.get("camera_parameters") or ())
        names = [k for k in report["parameters"] if not k.startswith(NOT_KINEMATIC) and k not in cams]
    else:
        raise DataError(
            f"{where}: no 'estimated_dh' or 'parameters' (is it the --json of jaxcal calibrate?)", option="params_from"
        )
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise DataError(f"{where}: 'estimated_dh' must be a list of parameter names", option="params_from")
    known = robot.param_names()
    unknown = [n for n in names if n not in known]
    if unknown:
        raise DataError(
            f"{where}: {', '.join(unknown)} {'is' if len(unknown) == 1 else 'are'} not a parameter of robot "
            f"{robot.name!r} (its parameters are {known[0]}..{known[-1]}); was the report made for another robot "
            f"({report.get('robot', 'unknown')!r})?",
            option="params_from",
        )
    out = {"params": ",".join(n for n in known if n in names) or "frames"}
    for key in ("estimate_base", "estimate_tool"):
        if isinstance(report.get(key), bool):
            out[key] = report[key]
    if isinstance(report.get("compliance"), bool):
        out["compliance"] = "yes" if report["compliance"] else "no"
    ridge = report.get("ridge_mm")
    if ridge is not None:
        if isinstance(ridge, bool) or not isinstance(ridge, (int, float)) or not ridge > 0:
            raise DataError(
                f"{where}: 'ridge_mm' must be a prior (mm) > 0 or null, got {ridge!r}", option="params_from"
            )
        out["ridge_mm"] = float(ridge)
    return out
