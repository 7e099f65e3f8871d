"""Measurement files (CSV): reading with validation, writing, and point-set registration.

## File format

One header row, then one row per pose. Columns are matched **by name** (any order):

| columns | meaning |
|---|---|
| `q1..qN` | joint values, one column per joint of the robot (all N required) |
| `x, y, z` | measured position of the tool point |
| `qw, qx, qy, qz` | optional: measured orientation, unit quaternion, **scalar first** |

Without the quaternion columns the data is *position-only*. Units: lengths in mm and angles in
rad unless `length_unit="m"` / `angle_unit="deg"` say otherwise; prismatic joints (`"P"`) take
the length unit. Everything is converted to mm and rad on reading.

Quaternions whose norm is within `1e-3` of 1 are normalised silently (files written with a
few decimals are fine); anything further off is refused. Every problem raises
`jaxcal.DataError` naming the file, the data row (1-based, header not counted; blank lines
skipped), its line in the file and the column. Implausible units (metres read as mm, degrees
read as rad, ...) raise a `UnitWarning` with the evidence.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import re
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from .errors import DataError

LENGTH_UNITS = {"mm": 1.0, "m": 1000.0}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
POSITION_COLUMNS = ("x", "y", "z")
QUAT_COLUMNS = ("qw", "qx", "qy", "qz")
QUAT_NORM_TOL = 1e-3
_JOINT_RE = re.compile(r"q([1-9][0-9]*)")


class UnitWarning(UserWarning):
    """The numbers in a measurement file look like they are in another unit than declared."""


def _frozen(a, dtype=np.float64) -> np.ndarray:
    a = np.array(a, dtype=dtype, copy=True)
    a.flags.writeable = False
    return a


@dataclasses.dataclass(frozen=True)
class Measurements:
    """Measured poses of a robot, in mm and rad (arrays are read-only copies).

    * `q` — `(K, n)` joint values (rad; mm for prismatic joints).
    * `poses` — `(K, 4, 4)` measured transforms, mm; rotation is the identity when
      `position_only`.
    * `source` — the file name, for messages.
    * `rows` — `(K,)` the 1-based CSV data-row numbers, kept through `subset` so messages after
      splitting or k-fold still point at the file.
    """

    q: np.ndarray
    poses: np.ndarray
    position_only: bool
    source: str
    rows: np.ndarray

    def __post_init__(self):
        q, poses, rows = _frozen(self.q), _frozen(self.poses), _frozen(self.rows, np.int64)
        if q.ndim != 2 or poses.shape != (q.shape[0], 4, 4) or rows.shape != (q.shape[0],):
            raise DataError(f"Measurements: inconsistent shapes q {q.shape}, poses {poses.shape}, "
                            f"rows {rows.shape}; expected (K, n), (K, 4, 4), (K,)")
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "poses", poses)
        object.__setattr__(self, "rows", rows)

    def __len__(self) -> int:
        return self.q.shape[0]

    @property
    def rows_per_pose(self) -> int:
        """Equations per pose: 3 (position) or 6 (position and orientation)."""
        return 3 if self.position_only else 6

    def subset(self, idx) -> "Measurements":
        """The poses selected by `idx` (indices, a boolean mask or a slice); rows are kept."""
        if not isinstance(idx, slice):
            idx = np.atleast_1d(np.asarray(idx))
        return dataclasses.replace(self, q=self.q[idx], poses=self.poses[idx], rows=self.rows[idx])


def franka_csv_path() -> Path:
    """Path of the bundled real data set `jaxcal/data/franka_panda_camera/measurements.csv`.

    114 poses of a Franka Panda with a flange camera; q in rad, positions in **metres**, so read
    it with `read_measurements(franka_csv_path(), preset("panda"), length_unit="m")`.
    """
    return Path(__file__).resolve().parent / "data" / "franka_panda_camera" / "measurements.csv"


def _unit(value, table, what, default):
    value = default if value is None else value
    if value not in table:
        raise DataError(f"{what} must be one of {', '.join(map(repr, table))}, got {value!r}")
    return table[value], value


def _names(cols) -> str:
    return ", ".join(repr(c) for c in cols)


def check_column_names(header, src, expected) -> dict[str, int]:
    """Map column name -> index; raise DataError for duplicated or unknown columns (``expected``
    describes the allowed ones in the message). Shared by the measurement and target readers."""
    seen: dict[str, int] = {}
    for i, name in enumerate(header):
        if name in seen:
            raise DataError(f"{src}: duplicated column name {name!r} (columns {seen[name] + 1} and {i + 1})")
        seen[name] = i
    unknown = [c for c in header if c not in POSITION_COLUMNS + QUAT_COLUMNS and not _JOINT_RE.fullmatch(c)]
    if unknown:
        raise DataError(f"{src}: unknown column(s) {_names(unknown)}; {expected}")
    return seen


def _check_header(header, n, src):
    """Map column name -> index; raise DataError for duplicated, unknown or missing columns."""
    expected = f"expected q1..q{n}, x, y, z and optionally qw, qx, qy, qz"
    seen = check_column_names(header, src, expected)
    joints = sorted(int(_JOINT_RE.fullmatch(c).group(1)) for c in header if _JOINT_RE.fullmatch(c))
    if joints != list(range(1, n + 1)):
        if joints and joints == list(range(1, len(joints) + 1)):
            raise DataError(f"{src}: robot has {n} joints, file has q1..q{len(joints)}")
        extra = [f"q{j}" for j in joints if not 1 <= j <= n]
        if extra:
            raise DataError(f"{src}: column(s) {_names(extra)} but the robot has {n} joints (q1..q{n})")
        missing = [f"q{j}" for j in range(1, n + 1) if j not in joints]
        raise DataError(f"{src}: missing column(s) {_names(missing)}; {expected}")
    missing = [c for c in POSITION_COLUMNS if c not in seen]
    if missing:
        raise DataError(f"{src}: missing column(s) {_names(missing)}; {expected}")
    present = [c for c in QUAT_COLUMNS if c in seen]
    if present and len(present) < 4:
        absent = [c for c in QUAT_COLUMNS if c not in seen]
        raise DataError(f"{src}: only some quaternion columns present ({', '.join(present)}; missing "
                        f"{', '.join(absent)}); give all of qw, qx, qy, qz or none")
    return seen, not present


def _parse_rows(records, header, src):
    """Float matrix of the data records; DataError for ragged rows and bad numbers."""
    values, rows, lines = [], [], []
    for k, (line, rec) in enumerate(records, start=1):
        where = f"{src}: row {k} (line {line})"
        if len(rec) != len(header):
            raise DataError(f"{where}: {len(rec)} fields, but the header has {len(header)} columns")
        out = []
        for name, text in zip(header, rec):
            try:
                v = float(text)
            except ValueError:
                what = "empty value" if not text.strip() else f"not a number: {text.strip()!r}"
                raise DataError(f"{where}, column {name!r}: {what}") from None
            if not math.isfinite(v):
                raise DataError(f"{where}, column {name!r}: value {text.strip()!r} is not finite")
            out.append(v)
        values.append(out)
        rows.append(k)
        lines.append(line)
    return np.array(values, dtype=np.float64), np.array(rows), np.array(lines)


def _read_records(path: Path):
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            records = []
            for rec in reader:
                if rec:  # skip blank lines
                    records.append((reader.line_num, [s.strip() for s in rec]))
    except FileNotFoundError:
        raise DataError(f"measurement file not found: {path}") from None
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise DataError(f"{path}: cannot read as a CSV text file: {e}") from None
    return records


def robot_reach(robot) -> float:
    """A rough reach in mm: sum of |a| and |d| over the DH table plus the tool offset norm."""
    dh = np.asarray(robot.dh)
    return float(np.abs(dh[:, 1]).sum() + np.abs(dh[:, 2]).sum() + np.linalg.norm(np.asarray(robot.tool)[:3, 3]))


def _unit_warnings(q, pos, robot, lu_name, lu, au_name, rows, src):
    revolute = np.array([t == "R" for t in robot.joint_types])
    prismatic_stroke = np.abs(q[:, ~revolute]).max(axis=0).sum() if (~revolute).any() else 0.0
    reach = robot_reach(robot) + prismatic_stroke
    span = float(np.ptp(pos, axis=0).max()) if len(pos) > 1 else None
    hint = "did you mean length_unit='{}' (--length-unit {})?"
    if span is not None and span < min(5.0, 0.01 * reach):
        warnings.warn(f"{src}: measured positions span only {span / lu:.3g} {lu_name} (largest x/y/z range) "
                      f"but the robot's reach is ~{reach:.0f} mm; " + hint.format("m", "m"), UnitWarning,
                      stacklevel=3)
    elif span is not None and span > 3.0 * reach:
        warnings.warn(f"{src}: measured positions span {span / lu:.3g} {lu_name} (largest x/y/z range), "
                      f"more than 3x the robot's reach (~{reach:.0f} mm); " + hint.format("mm", "mm"),
                      UnitWarning, stacklevel=3)
    if au_name == "rad" and revolute.any():
        qr = np.where(revolute, np.abs(q), 0.0)
        k, j = np.unravel_index(np.argmax(qr), qr.shape)
        if qr[k, j] > 2 * math.pi:
            warnings.warn(f"{src}: joint value {q[k, j]:.6g} at row {rows[k]}, column 'q{j + 1}' exceeds 2*pi "
                          f"in magnitude with angle_unit='rad'; were the joint angles written in degrees? "
                          f"did you mean angle_unit='deg' (--angle-unit deg)?", UnitWarning, stacklevel=3)


def _mixed_units(q, pos, robot, rows, src):
    """Raise `DataError` when some rows are in another unit than the rest: a few positions
    ~1000x closer to / farther from the measurement origin than the median row (metres among
    millimetres or the reverse), or a minority of rows with revolute joint values beyond both
    2*pi and the joint limits (degrees among radians)."""
    r = np.linalg.norm(pos, axis=1)
    med = float(np.median(r))
    if len(r) >= 3 and med > 0:
        odd = np.flatnonzero((r * 100 < med) | (r > 100 * med))
        if 0 < odd.size < len(r) / 2:
            k = odd[0]
            raise DataError(f"{src}: mixed length units? row {rows[k]}: position norm {r[k]:.4g} mm vs a median "
                            f"of {med:.4g} mm over all rows ({odd.size} such row(s): "
                            f"{', '.join(str(rows[i]) for i in odd[:5])}); write every row in the same unit")
    revolute = np.array([t == "R" for t in robot.joint_types])
    if revolute.any() and len(q) >= 3:
        lim = np.abs(np.asarray(robot.q_limits)).max(axis=1)
        bound = np.maximum(2 * math.pi, lim) * 1.05
        over = (np.abs(q) > bound) & revolute
        odd = np.flatnonzero(over.any(axis=1))
        if 0 < odd.size < len(q) / 2:
            k = odd[0]
            j = int(np.flatnonzero(over[k])[0])
            raise DataError(f"{src}: mixed angle units? row {rows[k]}, column 'q{j + 1}': {q[k, j]:.6g} rad is beyond "
                            f"2*pi and the joint limits while most rows are not ({odd.size} such row(s): "
                            f"{', '.join(str(rows[i]) for i in odd[:5])}); write every row in the same unit")


def open_table(path, expected: str):
    """``(path, source name, records, header)`` of a CSV; :class:`DataError` if it is empty
    (``expected`` says what the header should hold)."""
    path = Path(path)
    records = _read_records(path)
    if not records:
        raise DataError(f"{path}: file is empty; {expected}")
    return path, str(path), records, records[0][1]


def read_measurements(path, robot, *, length_unit=None, angle_unit=None) -> Measurements:
    """Read a measurement CSV (see the module docstring) for `robot`; returns mm and rad.

    `length_unit` is `"mm"` (default) or `"m"`, `angle_unit` is `"rad"` (default) or `"deg"`.
    Raises `DataError` for malformed files and warns `UnitWarning` for implausible units.
    """
    lu, lu_name = _unit(length_unit, LENGTH_UNITS, "length_unit", "mm")
    au, au_name = _unit(angle_unit, ANGLE_UNITS, "angle_unit", "rad")
    path, src, records, header = open_table(path, f"expected a header row q1..q{robot.n_joints},x,y,z[,qw,qx,qy,qz]")
    n = robot.n_joints
    cols, position_only = _check_header(header, n, src)
    if len(records) == 1:
        raise DataError(f"{src}: header only, no data rows")
    values, rows, lines = _parse_rows(records[1:], header, src)
    scale = np.array([lu if t == "P" else au for t in robot.joint_types])
    q = values[:, [cols[f"q{j}"] for j in range(1, n + 1)]] * scale
    pos = values[:, [cols[c] for c in POSITION_COLUMNS]] * lu
    poses = np.broadcast_to(np.eye(4), (len(values), 4, 4)).copy()
    poses[:, :3, 3] = pos
    if not position_only:
        quat = values[:, [cols[c] for c in QUAT_COLUMNS]]
        norm = np.linalg.norm(quat, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOL)
        if bad.size:
            k = bad[0]
            raise DataError(f"{src}: row {rows[k]} (line {lines[k]}): quaternion (qw, qx, qy, qz) has norm "
                            f"{norm[k]:.6g}, not 1 (tolerance {QUAT_NORM_TOL:g}); {bad.size} such row(s)")
        quat = quat / norm[:, None]
        poses[:, :3, :3] = Rotation.from_quat(quat[:, [1, 2, 3, 0]]).as_matrix()
    _mixed_units(q, pos, robot, rows, src)
    _unit_warnings(q, pos, robot, lu_name, lu, au_name, rows, src)
    return Measurements(q=q, poses=poses, position_only=position_only, source=path.name, rows=rows)


def write_measurements(path, q, poses, *, position_only=False) -> None:
    """Write `q` `(K, n)` (rad / mm) and `poses` `(K, 4, 4)` (mm) as a measurement CSV.

    Values are written in mm and rad with `repr` precision (they read back bit-identically;
    the orientation goes through a quaternion, exact to ~1e-16). Quaternions are written
    with `qw >= 0`. The caller's arrays are not modified.
    """
    q = np.array(q, dtype=np.float64, copy=True)
    poses = np.array(poses, dtype=np.float64, copy=True)
    if q.ndim != 2 or poses.ndim != 3 or poses.shape[1:] != (4, 4) or poses.shape[0] != q.shape[0]:
        raise DataError(f"write_measurements: q must be (K, n) and poses (K, 4, 4) with the same K; "
                        f"got q {q.shape}, poses {poses.shape}")
    for name, a in (("q", q), ("poses", poses)):
        if not np.isfinite(a).all():
            raise DataError(f"write_measurements: {name}[{int(np.argwhere(~np.isfinite(a))[0][0])}] is not finite")
    header = [f"q{j}" for j in range(1, q.shape[1] + 1)] + list(POSITION_COLUMNS)
    cols = [q, poses[:, :3, 3]]
    if not position_only:
        R = poses[:, :3, :3]
        err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2))
        if (err > 1e-6).any() or (np.linalg.det(R) < 0).any():
            k = int(np.argmax(np.where(np.linalg.det(R) < 0, np.inf, err)))
            raise DataError(f"write_measurements: poses[{k}] rotation is not a proper rotation matrix")
        xyzw = Rotation.from_matrix(R).as_quat()
        wxyz = xyzw[:, [3, 0, 1, 2]] * np.where(xyzw[:, 3:] < 0, -1.0, 1.0)
        header += list(QUAT_COLUMNS)
        cols.append(wxyz)
    table = np.concatenate(cols, axis=1)
    with Path(path).open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(header)
        w.writerows([repr(float(v)) for v in row] for row in table)


def check_enough_poses(meas: Measurements, n_params: int) -> None:
    """Raise `DataError` if the poses give fewer equations than `n_params` unknowns."""
    K, r = len(meas), meas.rows_per_pose
    if K * r < n_params:
        need = -(-n_params // r)
        raise DataError(f"{meas.source}: too few poses: {K} poses x {r} rows = {K * r} equations for "
                        f"{n_params} parameters; need at least {need} poses")


def register_points(P_from, P_to) -> np.ndarray:
    """Least-squares rigid transform `T` (4x4) with `T @ [p_from, 1] ~ [p_to, 1]` (Kabsch).

    Uses `scipy.spatial.transform.Rotation.align_vectors` on the centred point sets. Needs at
    least 3 corresponding points, not all on one line; raises `DataError` otherwise.
    """
    A = np.array(P_from, dtype=np.float64, copy=True)
    B = np.array(P_to, dtype=np.float64, copy=True)
    if A.ndim != 2 or A.shape[1] != 3 or A.shape != B.shape:
        raise DataError(f"register_points: need two (K, 3) arrays of the same shape, got {A.shape} and {B.shape}")
    if A.shape[0] < 3:
        raise DataError(f"register_points: need at least 3 points, got {A.shape[0]}")
    if not (np.isfinite(A).all() and np.isfinite(B).all()):
        raise DataError("register_points: points contain non-finite values")
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    Ac, Bc = A - ca, B - cb
    scale = max(np.abs(Ac).max(), np.abs(Bc).max(), 1e-300)
    for name, P in (("P_from", Ac), ("P_to", Bc)):
        if np.linalg.matrix_rank(P / scale, tol=1e-9) < 2:
            raise DataError(f"register_points: {name} points are (nearly) collinear; the rotation is not defined")
    rot, _ = Rotation.align_vectors(Bc, Ac)  # rot.apply(Ac) ~ Bc in the least-squares sense
    T = np.eye(4)
    T[:3, :3] = rot.as_matrix()
    T[:3, 3] = cb - T[:3, :3] @ ca
    return T
