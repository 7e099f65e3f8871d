"""Measurement files (CSV): reading with validation, and writing.

## File format

One header row, then one row per pose. Columns are matched **by name** (any order):

| columns | meaning |
|---|---|
| `q1..qN`, or the robot's joint names | joint values, one column per joint (all required) |
| `x, y, z` | measured position of the tool point |
| `x1, y1, z1 ... xM, yM, zM` | instead: M points on the tool (e.g. motion-capture markers) |
| `qw, qx, qy, qz` | optional with `x, y, z`: measured orientation, unit quaternion, **scalar first** |

Without the quaternion columns the data are positions. Other columns (timestamps, notes) are
ignored and listed in :attr:`Measurements.ignored`.

**Lost points.** Without quaternions, a point whose three cells are all empty (or ``nan``) at a
row was not seen there (an occluded marker): it is NaN in :attr:`Measurements.measured` and a
calibration gives it no weight; the pose keeps its other points. A row with no point left is
dropped (:attr:`Measurements.dropped_rows`). With quaternions, a row whose seven measurement
cells are all empty (or ``nan``: the camera did not find its target there) is dropped likewise.
Some of a point's (or a pose's) cells empty and others not, or a cell that is not a number, is
an error naming the cell.

**Units follow the files**: lengths and angles are read in the robot file's units
(``robot.units``, e.g. a URDF's metres) unless ``length_unit`` / ``angle_unit`` say otherwise;
prismatic joints take the length unit. Everything is converted to mm and rad on reading.

Quaternions whose norm is within ``1e-3`` of 1 are normalised silently (files written with a few
decimals are fine); anything further off is refused. Every problem raises
:class:`jaxcal.DataError` naming the file, the data row (1-based, header not counted; blank lines
and lines of empty fields skipped), its line in the file and the column. Rows in another unit than the rest (metres
among millimetres, degrees among radians) are refused by row; a whole file in another unit is
refused by the calibration's unit check (:func:`jaxcal.calibrate`), which compares it with the
robot.
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import math
import re
from pathlib import Path

import numpy as np

from ._io import write_atomic
from .errors import DataError
from .lie import quat_to_matrix
from .robot import ANGLE_UNITS, LENGTH_UNITS, Robot

POSITION_COLUMNS = ("x", "y", "z")
QUAT_COLUMNS = ("qw", "qx", "qy", "qz")
QUAT_NORM_TOL = 1e-3
MIXED_ANGLE_FACTOR = 3.0
"""A reading of a joint without limits of its own, beyond a full turn, is taken for another unit
(degrees among radians) when it is beyond this many times the column's largest reading within a
turn; readings running on over several turns stay closer."""
_JOINT_RE = re.compile(r"q([1-9][0-9]*)")
_MEASUREMENT_RE = re.compile(r"[xyz]([1-9][0-9]*)?|q[wxyz]")
_ORIENTATION_RE = re.compile(
    r"(?i)r[1-3][1-3]|roll|pitch|yaw|r[xyz]|rot.*|euler.*|quat.*|q_?[wxyz]|o[wxyz]|.*orient.*|[abcwpr]"
)


def orientation_like(names) -> list[str]:
    """The column names among ``names`` that look like an orientation jaxcal does not read
    (a rotation matrix r11..r33, roll/pitch/yaw, a rotation vector rx, ry, rz, KUKA's A, B, C,
    Fanuc's W, P, R, a quaternion under other names: QW, q_w, ow, ROS's orientation.w): only
    quaternions qw, qx, qy, qz are read as orientations."""
    return [c for c in names if _ORIENTATION_RE.fullmatch(c.strip())]


_POINT_RE = re.compile(r"([xyz])([1-9][0-9]*)")


def _frozen(a, dtype=np.float64) -> np.ndarray:
    a = np.array(a, dtype=dtype, copy=True)
    a.flags.writeable = False
    return a


@dataclasses.dataclass(frozen=True)
class Measurements:
    """Measured poses or points of a robot, in mm and rad (arrays are read-only copies).

    * ``q`` — ``(K, n)`` joint values (rad; mm for prismatic joints).
    * ``measured`` — ``(K, 4, 4)`` measured tool poses, or ``(K, M, 3)`` measured points.
    * ``source`` — the file name, for messages.
    * ``rows`` — ``(K,)`` 1-based CSV data-row numbers, kept through :meth:`subset` so messages
      after splitting or cross-validation still point at the file.
    * ``ignored`` — the file's columns that are neither joints nor measurements.
    * ``ignored_ranges`` — the lowest and highest number of each ignored column that holds only
      numbers, as written (a joint of the robot file outside the chain, still moving, shows here).
    * ``units`` — the ``(length, angle)`` units the file was read in.
    * ``dropped_rows`` — data rows left out because none of their points was seen.
    * ``point_numbers`` — the file's number of each measured point (after :meth:`select_points`,
      or of a file that leaves a number out); empty: 1..M.

    A point not seen at a pose (a lost marker) is NaN in ``measured`` (:attr:`lost_points`).
    """

    q: np.ndarray
    measured: np.ndarray
    source: str = "arrays"
    rows: np.ndarray | None = None
    ignored: tuple[str, ...] = ()
    ignored_ranges: dict = dataclasses.field(default_factory=dict)
    units: tuple[str, str] = ("mm", "rad")
    dropped_rows: tuple[int, ...] = ()
    point_numbers: tuple[int, ...] = ()

    def __post_init__(self):
        q, meas = _frozen(self.q), _frozen(self.measured)
        rows = np.arange(1, len(q) + 1) if self.rows is None else self.rows
        rows = _frozen(rows, np.int64)
        K = q.shape[0] if q.ndim == 2 else -1
        ok = (
            q.ndim == 2
            and rows.shape == (K,)
            and (meas.shape == (K, 4, 4) or (meas.ndim == 3 and meas.shape[0] == K and meas.shape[2] == 3))
        )
        if not ok:
            raise DataError(
                f"Measurements: inconsistent shapes q {q.shape}, measured {meas.shape}, rows {rows.shape}; "
                f"expected (K, n), (K, 4, 4) or (K, M, 3), (K,)"
            )
        M = 0 if meas.shape[1:] == (4, 4) else meas.shape[1]
        nums = tuple(self.point_numbers)
        if nums and (
            len(nums) != M or len(set(nums)) != M or not all(isinstance(j, (int, np.integer)) and j >= 1 for j in nums)
        ):
            raise DataError(
                f"Measurements: point_numbers {nums!r} must give each of the {M} measured points its number in the "
                f"file (1, 2, ...), each once"
            )
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "measured", meas)
        object.__setattr__(self, "rows", rows)
        object.__setattr__(self, "point_numbers", tuple(int(j) for j in nums))

    def __len__(self) -> int:
        return self.q.shape[0]

    @property
    def n_points(self) -> int:
        """Points per pose, or 0 for poses."""
        return 0 if self.measured.shape[1:] == (4, 4) else self.measured.shape[1]

    @property
    def position_only(self) -> bool:
        return self.n_points > 0

    @property
    def poses(self) -> np.ndarray:
        """``(K, 4, 4)`` measured poses; for points, the first point as a translation."""
        if self.n_points == 0:
            return self.measured
        out = np.broadcast_to(np.eye(4), (len(self), 4, 4)).copy()
        out[:, :3, 3] = self.measured[:, 0]
        return out

    @property
    def numbers(self) -> tuple[int, ...]:
        """The file's number of each measured point (:attr:`point_numbers`, else 1..M)."""
        return self.point_numbers or tuple(range(1, self.n_points + 1))

    @property
    def lost_points(self) -> list[tuple[int, int]]:
        """``(data row, point number in the file)`` of every point not seen (NaN), in file order."""
        if self.n_points == 0:
            return []
        numbers = self.numbers
        lost = np.argwhere(np.isnan(self.measured).any(-1))
        return [(int(self.rows[k]), numbers[j]) for k, j in lost]

    @property
    def rows_per_pose(self) -> int:
        return 6 if self.n_points == 0 else 3 * self.n_points

    def subset(self, idx) -> "Measurements":
        """The poses selected by ``idx`` (indices, a boolean mask or a slice); rows are kept."""
        if not isinstance(idx, slice):
            idx = np.atleast_1d(np.asarray(idx))
        return dataclasses.replace(self, q=self.q[idx], measured=self.measured[idx], rows=self.rows[idx])

    def select_points(self, points) -> "Measurements":
        """Only the measured points numbered ``points`` (the file's numbers, as the columns ``x1 ..
        xM``: :attr:`numbers`); a pose none of whose selected points was seen is dropped
        (:attr:`dropped_rows`)."""
        if self.n_points == 0:
            raise DataError(f"{self.source}: measures poses, not points; points apply to x1,y1,z1 ... data")
        idx = [int(p) for p in np.atleast_1d(points)]
        numbers = self.numbers
        bad = [p for p in idx if p not in numbers]
        if bad or not idx or len(set(idx)) != len(idx):
            plain = numbers == tuple(range(1, self.n_points + 1))
            have = f"1..{self.n_points}" if plain else ", ".join(map(str, numbers))
            raise DataError(f"{self.source}: {idx} (points) must be distinct point numbers in {have}", option="points")
        meas = self.measured[:, [numbers.index(p) for p in idx]]
        seen = ~np.isnan(meas).any(-1).all(-1)
        if not seen.any():
            raise DataError(f"{self.source}: point(s) {idx} (points) were not seen in any row", option="points")
        gone = tuple(int(r) for r in self.rows[~seen])
        out = dataclasses.replace(
            self, measured=meas, dropped_rows=tuple(sorted(self.dropped_rows + gone)), point_numbers=tuple(idx)
        )
        return out.subset(seen) if gone else out


def franka_csv_path() -> Path:
    """Path of the bundled real data set ``jaxcal/data/franka_panda_camera/measurements.csv``.

    114 poses of a Franka Panda with a flange camera; q in rad, positions in **metres**, so read
    it with ``read_measurements(franka_csv_path(), preset("panda"), length_unit="m")``.
    """
    return Path(__file__).resolve().parent / "data" / "franka_panda_camera" / "measurements.csv"


def tiago_paths() -> tuple[Path, Path]:
    """``(urdf, csv)`` of the bundled real data set ``jaxcal/data/tiago_mocap``: a TIAGo arm
    (prismatic torso + 7 joints) as a URDF chain and 37 postures with four motion-capture points
    on the hand, in metres (the file's units follow the URDF)."""
    d = Path(__file__).resolve().parent / "data" / "tiago_mocap"
    return d / "tiago_arm.urdf", d / "training.csv"


def unit_scale(value, table, what: str, default: str) -> tuple[float, str]:
    """``(scale to mm or rad, name)`` of a unit option; None takes ``default``."""
    value = default if value is None else value
    if value not in table:
        raise DataError(f"{what} must be one of {', '.join(map(repr, table))}, got {value!r}", option=what)
    return table[value], value


def _names(cols) -> str:
    return ", ".join(repr(c) for c in cols)


def _header_read(header) -> str:
    """What the header was read as, for a file whose columns were not found: names are matched
    exactly (case and all), and a header read as one field shows a delimiter not understood."""
    shown = _names(header[:10]) + (f", ... ({len(header)} columns)" if len(header) > 10 else "")
    return f"the header was read as {shown} (names are matched exactly; columns separated by ',', ';' or tab)"


def _records(lines: list[str]) -> list[tuple[int, list[str]]]:
    """``(line number, fields)`` of the lines that hold data. Spreadsheet exports are read as
    written: ``#`` comment lines and Excel's ``sep=;`` line before the header, and lines of empty
    fields (``,,,``: formatted empty cells) anywhere, are skipped; the delimiter is the header's:
    of a comma, a semicolon and a tab, the one that splits it into most names (a comma inside a
    name of a semicolon file is part of the name). A ``#`` line below the header is a row, which
    :func:`read_table` refuses unless every row starts so (a column of ids ``#1``, ``#2``)."""
    start, delimiter = 0, None
    while start < len(lines):
        text = lines[start].lstrip(" ").rstrip("\r\n ")  # a tab may be the separator sep= names
        if delimiter is None and text.lower().startswith("sep=") and len(text) == 5:
            delimiter = text[4]
        elif text.strip(" ,;\t") and not text.startswith("#"):  # a line of empty cells is blank too
            break
        start += 1
    if delimiter is None and start < len(lines):  # the one that splits the header into most names
        head = lines[start]
        delimiter = max((",", ";", "\t"), key=lambda d: len(next(csv.reader([head], delimiter=d))))
    reader = csv.reader(lines[start:], delimiter=delimiter or ",")
    out, first = [], start + 1  # a record's first line (a quoted field may span several)
    for rec in reader:
        if any(fields := [v.strip() for v in rec]):
            out.append((first, fields))
        first = start + reader.line_num + 1
    return out


def _fitted_to(header: list[str], rec: list[str]) -> list[str]:
    """``rec`` with as many fields as ``header`` where the two differ only by trailing empty fields
    (a spreadsheet's trailing separators on some lines, or on the header alone); else as it is."""
    n_head = len(header) - len(list(itertools.takewhile(lambda v: not v, reversed(header))))
    n_rec = len(rec) - len(list(itertools.takewhile(lambda v: not v, reversed(rec))))
    if len(rec) != len(header) and n_head <= len(rec) and n_rec <= len(header):
        return (rec + [""] * len(header))[: len(header)]
    return rec


def _decoded(raw: bytes, path) -> str:
    """The file's text: UTF-8 (with or without a byte-order mark), UTF-16 with its mark (Excel's
    "Unicode text"), else Windows-1252 (Excel's "CSV" on Windows; the numbers read the same)."""
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        return raw.decode("utf-16")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        try:
            return raw.decode("cp1252")
        except UnicodeDecodeError as e:  # the byte neither reads
            line = raw[: e.start].count(b"\n") + 1
            raise DataError(
                f"{path}: line {line}: byte {raw[e.start]:#04x} is neither UTF-8 nor Windows-1252 text; save the "
                f"file as CSV UTF-8"
            ) from None


def read_table(path, expected: str, what: str = "measurement"):
    """``(source name, header, records)`` of a CSV, records as ``(line, fields)`` with blank lines
    skipped; :class:`DataError` if the file (``what``: the kind it names) is missing, unreadable or
    empty (``expected`` says what the header should hold) or repeats a column name."""
    path = Path(path)
    try:
        records = _records(_decoded(path.read_bytes(), path).splitlines())
    except FileNotFoundError:
        raise DataError(f"{what} file not found: {path}") from None
    except (OSError, UnicodeError, csv.Error) as e:
        raise DataError(f"{path}: cannot read as a CSV text file: {e}") from None
    if not records:
        raise DataError(f"{path}: file is empty; {expected}")
    header = records[0][1]
    seen: dict[str, int] = {}
    for i, name in enumerate(header):
        if name in seen and name.strip():  # empty names: trailing separators (Excel's ;;), no data
            clash = (
                "; if a joint is named like a measurement column (x, y, z, qw..qz, x1..), write the joint "
                "columns as q1..qN, or rename the joint in the robot file"
                if _MEASUREMENT_RE.fullmatch(name)
                else ""
            )
            raise DataError(f"{path}: duplicated column name {name!r} (columns {seen[name] + 1} and {i + 1}){clash}")
        seen[name] = i
    rows = records[1:]
    # a row commented out below the header: refused, whatever its columns (an ignored first column
    # would let it through as data); a first column of ids that all start with '#' is data
    hashed = [k for k, (_, rec) in enumerate(rows) if rec[0].startswith("#")]
    if hashed and len(hashed) < len(rows):
        k = hashed[0]
        raise DataError(
            f"{path}: row {k + 1} (line {rows[k][0]}) starts with '#': comment lines go before the header; delete "
            f"the row, or its '#' ({len(hashed)} such row(s))"
        )
    return str(path), header, [(line, _fitted_to(header, rec)) for line, rec in rows]


def require_rows(records, src: str) -> None:
    if not records:
        raise DataError(f"{src}: header only, no data rows")


def joint_columns(header, robot: Robot, src: str, *, required: bool = True) -> list[str] | None:
    """The joint columns of a header, in joint order: ``q1..qN`` or the robot's joint names.
    None when there are none and ``required`` is False."""
    n = robot.n_joints
    default = tuple(f"q{j}" for j in range(1, n + 1))
    # a joint named like a measurement column (a gantry's x, a lift's z) is read by its number
    by_number = any(_JOINT_RE.fullmatch(c) for c in header)
    names = [c for c in robot.joint_names if not (by_number and _MEASUREMENT_RE.fullmatch(c))]
    named = [] if tuple(robot.joint_names) == default else [c for c in names if c in header]
    numbered = sorted((int(m.group(1)), c) for c in header if (m := _JOINT_RE.fullmatch(c)))
    in_numbers = {c for _, c in numbered}
    if named and len(named) == n and (not numbered or in_numbers <= set(named)):
        return list(robot.joint_names)  # names that look numbered (q2, q1, ...) are still the names
    if named and numbered and [c for _, c in numbered] != named:
        raise DataError(
            f"{src}: joint columns both numbered ({_names(c for _, c in numbered)}) and named "
            f"({_names(named)}); use one scheme"
        )
    if named and len(named) < n:
        missing = [c for c in robot.joint_names if c not in header]
        raise DataError(
            f"{src}: missing joint column(s) {_names(missing)} (the robot's joints are {_names(robot.joint_names)})"
        )
    expected = f"expected q1..q{n} or the joint names {_names(robot.joint_names)}"
    if not numbered:
        if required:
            raise DataError(f"{src}: no joint columns; {expected}; {_header_read(header)}")
        return None
    idx = [j for j, _ in numbered]
    if "q0" in header and idx == list(range(1, n)):
        raise DataError(f"{src}: joint columns q0..q{n - 1}: jaxcal numbers joints from 1; name them q1..q{n}")
    if idx != list(range(1, n + 1)):
        if idx == list(range(1, len(idx) + 1)):
            raise DataError(f"{src}: robot has {n} joints, file has q1..q{len(idx)}")
        extra = [f"q{j}" for j in idx if not 1 <= j <= n]
        if extra:
            raise DataError(f"{src}: column(s) {_names(extra)} but the robot has {n} joints (q1..q{n})")
        missing = [f"q{j}" for j in range(1, n + 1) if j not in idx]
        raise DataError(f"{src}: missing column(s) {_names(missing)}; {expected}")
    return [f"q{j}" for j in range(1, n + 1)]


def measurement_columns(header, src: str, *, required: bool = True):
    """``(position columns per point, quaternion columns or None)``: ``x, y, z`` (one point) or
    ``x1..zM`` (the points numbered in the file, in order: a number without columns, a marker
    the file leaves out, is none of them; :func:`point_numbers_of`), and ``qw, qx, qy, qz`` for
    full poses."""
    expected = "expected x, y, z [qw, qx, qy, qz], or x1, y1, z1 ... xM, yM, zM"
    single = [c for c in POSITION_COLUMNS if c in header]
    numbered: dict[int, dict[str, str]] = {}
    for c in header:
        if m := _POINT_RE.fullmatch(c):
            numbered.setdefault(int(m.group(2)), {})[m.group(1)] = c
    quat = [c for c in QUAT_COLUMNS if c in header]
    if single and numbered:
        raise DataError(
            f"{src}: both x, y, z and numbered point columns "
            f"({_names(c for j in sorted(numbered) for c in numbered[j].values())}); "
            f"use one scheme; {expected}"
        )
    if single:
        if len(single) < 3:
            raise DataError(
                f"{src}: missing column(s) {_names(c for c in POSITION_COLUMNS if c not in header)}; {expected}"
            )
        points = [list(POSITION_COLUMNS)]
    elif numbered:
        for j, have in sorted(numbered.items()):
            if len(have) < 3:
                missing = [f"{a}{j}" for a in "xyz" if a not in have]
                raise DataError(f"{src}: point {j}: missing column(s) {_names(missing)}; {expected}")
        points = [[numbered[j][a] for a in "xyz"] for j in sorted(numbered)]
    else:
        if required:
            raise DataError(f"{src}: missing column(s) 'x', 'y', 'z'; {expected}; {_header_read(header)}")
        points = []
    if quat and len(quat) < 4:
        absent = [c for c in QUAT_COLUMNS if c not in header]
        raise DataError(
            f"{src}: only some quaternion columns present ({', '.join(quat)}; missing "
            f"{', '.join(absent)}); give all of qw, qx, qy, qz or none"
        )
    if quat and len(points) != 1:
        raise DataError(
            f"{src}: quaternion columns need exactly one point (x, y, z); the file has {len(points)} points"
        )
    return points, (list(QUAT_COLUMNS) if quat else None)


def point_numbers_of(points) -> tuple[int, ...]:
    """The file's number of each point of :func:`measurement_columns` (``x, y, z``: 1)."""
    return tuple(int(_POINT_RE.fullmatch(c[0]).group(2)) if _POINT_RE.fullmatch(c[0]) else 1 for c in points)


def parse_rows(records, header, columns, src, *, points=()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Float matrix of ``columns`` of the data records, with their row and line numbers;
    :class:`DataError` for ragged rows and bad numbers (other columns are not parsed).
    ``points``: groups of columns (a point's x, y, z, or a pose's seven) that may be lost
    together: all of them empty or ``nan`` give NaN; some of them is an error naming the cell."""
    idx = [header.index(c) for c in columns]
    groups = [[columns.index(c) for c in g] for g in points]
    values, rows, lines = [], [], []
    for k, (line, rec) in enumerate(records, start=1):
        where = f"{src}: row {k} (line {line})"
        if len(rec) != len(header):
            raise DataError(f"{where}: {len(rec)} fields, but the header has {len(header)} columns")
        out = []
        for name, i in zip(columns, idx):
            text = rec[i].strip()
            try:
                if "_" in text:  # Python reads 1_000 as 1000; no data file means that
                    raise ValueError(text)
                v = float(text) if text else math.nan
            except ValueError:
                comma = " (a decimal comma? write decimals with a point)" if re.fullmatch(r"[-+]?\d*,\d+", text) else ""
                raise DataError(f"{where}, column {name!r}: not a number: {text!r}{comma}") from None
            if math.isinf(v):
                raise DataError(f"{where}, column {name!r}: value {text!r} is not finite")
            out.append(v)
        lost = set()
        for g in groups:
            gap = [j for j in g if math.isnan(out[j])]
            if gap and len(gap) < len(g):
                given = ", ".join(repr(columns[j]) for j in g if j not in gap)
                what, cells = ("point", "all three") if len(g) == 3 else ("pose", f"all {len(g)} of its cells")
                raise DataError(
                    f"{where}, column {columns[gap[0]]!r}: {_missing(rec[idx[gap[0]]])}, but {given} of the same "
                    f"{what} {'is' if len(g) - len(gap) == 1 else 'are'} not; a {what} not seen leaves {cells} empty"
                )
            lost.update(gap)
        for j, v in enumerate(out):
            if math.isnan(v) and j not in lost:
                raise DataError(f"{where}, column {columns[j]!r}: {_missing(rec[idx[j]])}")
        values.append(out)
        rows.append(k)
        lines.append(line)
    return np.array(values, dtype=np.float64).reshape(len(records), len(columns)), np.array(rows), np.array(lines)


def _missing(text: str) -> str:
    return "empty value" if not text.strip() else f"value {text.strip()!r} is not finite"


def quaternions_to_rotations(quat, rows, lines, src) -> np.ndarray:
    """Rotation matrices of scalar-first unit quaternions ``(K, 4)``; near-unit ones normalised,
    others refused naming the row."""
    norm = np.linalg.norm(quat, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOL)
    if bad.size:
        k = bad[0]
        raise DataError(
            f"{src}: row {rows[k]} (line {lines[k]}): quaternion (qw, qx, qy, qz) has norm "
            f"{norm[k]:.6g}, not 1 (tolerance {QUAT_NORM_TOL:g}); {bad.size} such row(s)"
        )
    return quat_to_matrix(quat / norm[:, None])


QUATERNION_MISTAKES = (
    "quaternion written x, y, z, w",
    "quaternion written w, x, y, z under names x, y, z, w",
    "quaternion of the inverse rotation",
)
"""The ways a file's quaternions are commonly written other than read (:func:`rotations_without`)."""


def rotations_without(R: np.ndarray) -> dict[str, np.ndarray]:
    """``{mistake: rotations}``: rotation matrices ``R (..., 3, 3)`` as read, taken again as they
    would be without each mistake of :data:`QUATERNION_MISTAKES` (a scalar-last quaternion under
    scalar-first names, the reverse, or the inverse rotation: JPL's convention, or the frame's
    inverse)."""
    from scipy.spatial.transform import Rotation

    R = np.asarray(R, dtype=np.float64)
    xyzw = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat()
    out = {}
    # the read w, x, y, z fields taken as x, y, z, w; then the read x, y, z, w taken as w, x, y, z
    for name, order in zip(QUATERNION_MISTAKES[:2], ([3, 0, 1, 2], [1, 2, 3, 0])):
        out[name] = Rotation.from_quat(xyzw[:, order]).as_matrix().reshape(R.shape)
    out[QUATERNION_MISTAKES[2]] = np.swapaxes(R, -1, -2)
    return out


def mixed_units(q, pos, robot: Robot, rows, src, joint_cols, point_numbers=()) -> None:
    """Raise :class:`DataError` when some rows are in another unit than the rest: a few positions
    ~1000x closer to / farther from the measurement origin than the median row (metres among
    millimetres or the reverse), or a minority of rows with revolute joint values beyond both
    2*pi and the joint limits (degrees among radians). Points are named by their numbers in the
    file (``point_numbers``, else 1..M)."""
    per_point = np.linalg.norm(pos, axis=-1)
    several = per_point.ndim > 1 and per_point.shape[-1] > 1
    nums = list(point_numbers) or list(range(1, (per_point.shape[-1] if per_point.ndim > 1 else 1) + 1))
    if several and len(per_point) >= 3:
        zero = per_point == 0.0  # exactly 0, 0, 0: never measured, an export's stand-in for a lost marker
        most = np.flatnonzero(zero.sum(0) > len(per_point) / 2)
        if most.size:  # fewer are outliers, found and named; these would be the fit's majority
            j = int(most[0])
            raise DataError(
                f"{src}: point {nums[j]} is at exactly 0, 0, 0 in {int(zero[:, j].sum())} of {len(per_point)} rows: "
                f"lost markers written as zeros? Write them as empty cells (that point is then left out where "
                f"lost), or leave the point out (--points)"
            )
    # a row's nearest point: another unit moves every point, a sentinel (-9999) only the lost one
    with np.errstate(invalid="ignore"):
        r = np.nanmin(np.where(per_point > 0, per_point, np.nan), -1) if several else per_point.reshape(len(pos))
    r = np.where(np.isfinite(r), r, 0.0)
    med = float(np.median(r))
    if several and len(r) >= 3 and med > 0:
        far = (per_point > 100 * med) & (r[:, None] <= 100 * med)
        if far.any():  # in any number of rows: the other points say what the row's unit is
            k, j = (int(i) for i in np.argwhere(far)[0])
            odd = np.flatnonzero(far.any(-1))
            raise DataError(
                f"{src}: row {rows[k]}, point {nums[j]}: position norm {per_point[k, j]:.4g} mm while the row's "
                f"other points and the median row are near {med:.4g} mm: a lost marker written as a sentinel "
                f"value (such as -9999)? Write lost markers as empty cells ({odd.size} such row(s): "
                f"{', '.join(str(rows[i]) for i in odd[:5])})"
            )
    if len(r) >= 3 and med > 0:
        # a row at exactly 0, 0, 0 is a lost marker exported as zeros, not another unit: an outlier
        odd = np.flatnonzero(((r * 100 < med) & (r > 0)) | (r > 100 * med))
        if 0 < odd.size < len(r) / 2:
            k = odd[0]
            # one point alone cannot tell a far row's unit from a lost marker's sentinel value
            sentinel = ", or a lost marker written as a sentinel value" if (r[odd] > 100 * med).any() else ""
            raise DataError(
                f"{src}: mixed length units{sentinel}? row {rows[k]}: position norm {r[k]:.4g} mm vs a median "
                f"of {med:.4g} mm over all rows ({odd.size} such row(s): "
                f"{', '.join(str(rows[i]) for i in odd[:5])}); write every row in the same unit, and lost "
                f"markers as empty cells"
            )
    revolute = np.array([t == "R" for t in robot.joint_types])
    if revolute.any() and len(q) >= 3:
        lim = np.abs(np.asarray(robot.q_limits)).max(axis=1)
        bound = np.maximum(2 * math.pi, lim) * 1.05
        over = (np.abs(q) > bound) & revolute
        # a joint without limits of its own may turn several times (a URDF continuous joint): its
        # reading beyond a turn is another unit only far beyond the column's other readings
        within = np.where(np.abs(q) <= bound, np.abs(q), 0.0).max(axis=0)
        over &= robot.limits_given() | (np.abs(q) > MIXED_ANGLE_FACTOR * within)
        odd = np.flatnonzero(over.any(axis=1))
        if 0 < odd.size < len(q) / 2:
            k = odd[0]
            j = int(np.flatnonzero(over[k])[0])
            turns = round(q[k, j] / (2 * math.pi))
            lo, hi = np.asarray(robot.q_limits)[j]
            wrap = (
                f", or a reading off by a whole turn (an encoder's wrap: {q[k, j] - 2 * math.pi * turns:.6g} rad is "
                f"within the limits)"
                if abs(turns) == 1 and lo <= q[k, j] - 2 * math.pi * turns <= hi
                else ""
            )
            raise DataError(
                f"{src}: mixed angle units{wrap}? row {rows[k]}, column {joint_cols[j]!r}: {q[k, j]:.6g} rad is "
                f"beyond 2*pi and the joint limits while most rows are not ({odd.size} such row(s): "
                f"{', '.join(str(rows[i]) for i in odd[:5])}); write every row in the same unit"
            )


def _numeric_ranges(header, records, names) -> dict[str, tuple[float, float]]:
    """``(lowest, highest)`` of each column of ``names`` whose filled cells are all numbers."""
    out = {}
    for name in names:
        if name not in header:
            continue
        i = header.index(name)
        cells = [r[i].strip() for _, r in records if i < len(r) and r[i].strip()]
        try:
            v = np.array([float(c) for c in cells])
        except ValueError:
            continue
        if v.size and np.isfinite(v).all():
            out[name] = (float(v.min()), float(v.max()))
    return out


MOVED_RAD, MOVED_MM = 1e-2, 1.0
"""How far a joint outside the chain may move over the file before :func:`joints_left_out`
names it: beyond a reading's jitter, as :func:`jaxcal.evaluate` tells a repeated posture."""


def joints_left_out(meas: Measurements, robot: Robot, movable: dict[str, str]) -> dict[str, str]:
    """Warnings for the file's columns named after a movable joint of the robot file above the
    chain's base (``movable``: name -> ``"R"``/``"P"``, :func:`jaxcal.robot.read_movable_joints`)
    that moves over the rows, by joint name: the model holds the base still, so that motion is
    fitted into the other parameters, or refused."""
    lu, au = LENGTH_UNITS[meas.units[0]], ANGLE_UNITS[meas.units[1]]
    out = {}
    for name, (lo, hi) in meas.ignored_ranges.items():
        kind = movable.get(name)
        if kind is None or name in robot.joint_names:
            continue
        span, unit = ((hi - lo) * lu, "mm") if kind == "P" else ((hi - lo) * au, "rad")
        if span > (MOVED_MM if kind == "P" else MOVED_RAD):
            out[name] = (
                f"column {name!r} is a joint of the robot file above the chain calibrated "
                f"({', '.join(robot.joint_names)}), and it moves over the rows (by {span:.4g} {unit}): the model "
                f"takes it as fixed, so its motion is fitted into the other parameters; include it in the chain "
                f"(--base-link above it) or use rows where it stands still"
            )
    return out


def read_measurements(
    path, robot: Robot, *, length_unit=None, angle_unit=None, points=None, drop_unseen: bool = False
) -> Measurements:
    """Read a measurement CSV (module docstring) for ``robot``; returns mm and rad.

    ``length_unit`` (``"mm"`` or ``"m"``) and ``angle_unit`` (``"rad"`` or ``"deg"``) default to
    the robot file's units (``robot.units``). ``points``: only these measured points
    (:meth:`Measurements.select_points`), chosen before the unit checks, so that a point left out
    (a marker lost and written as a sentinel) does not refuse the file. A point empty in every
    row is refused by its columns, or with ``drop_unseen`` left out (a file read for its joint
    values alone). Raises :class:`DataError` for malformed files.
    """
    lu, lu_name = unit_scale(length_unit, LENGTH_UNITS, "length_unit", robot.units[0])
    au, au_name = unit_scale(angle_unit, ANGLE_UNITS, "angle_unit", robot.units[1])
    n = robot.n_joints
    src, header, records = read_table(path, f"expected a header row q1..q{n},x,y,z[,qw,qx,qy,qz]")
    jcols = joint_columns(header, robot, src)
    columns, quat = measurement_columns(header, src)
    pcols = [c for p in columns for c in p]
    used = set(jcols) | set(pcols) | set(quat or [])
    # a column without a name is listed only where it holds data (not a trailing comma's)
    ignored = tuple(
        c if c.strip() else f"column {i + 1} (no name)"
        for i, c in enumerate(header)
        if c not in used and (c.strip() or any(i < len(r) and r[i].strip() for _, r in records))
    )
    require_rows(records, src)
    ignored_ranges = _numeric_ranges(header, records, ignored)
    # a pose not measured (the camera did not find the target) leaves its seven cells empty
    groups = [columns[0] + quat] if quat else columns
    values, rows, lines = parse_rows(records, header, jcols + pcols + (quat or []), src, points=groups)
    seen = (~np.isnan(values[:, n : n + len(pcols)]).reshape(len(values), len(columns), 3).any(-1)).any(-1)
    if not seen.any():
        raise DataError(f"{src}: no row has a measured point (every point cell is empty)")
    dropped = tuple(int(r) for r in rows[~seen])
    values, rows, lines = values[seen], rows[seen], lines[seen]
    scale = np.array([lu if t == "P" else au for t in robot.joint_types])
    q = values[:, :n] * scale
    pos = values[:, n : n + len(pcols)].reshape(len(values), len(columns), 3) * lu
    if quat:
        meas = np.broadcast_to(np.eye(4), (len(values), 4, 4)).copy()
        meas[:, :3, 3] = pos[:, 0]
        meas[:, :3, :3] = quaternions_to_rotations(values[:, n + 3 :], rows, lines, src)
    else:
        meas = pos
    numbers = () if quat else point_numbers_of(columns)
    numbers = () if numbers == tuple(range(1, len(numbers) + 1)) else numbers  # 1..M: the default
    out = Measurements(
        q=q,
        measured=meas,
        source=Path(path).name,
        rows=rows,
        ignored=ignored,
        ignored_ranges=ignored_ranges,
        units=(lu_name, au_name),
        dropped_rows=dropped,
        point_numbers=numbers,
    )
    if points is not None:
        out = out.select_points(points)
        q, pos, rows = out.q, out.measured, out.rows
    never = [j for j in range(out.n_points) if np.isnan(out.measured[:, j]).all()]
    if never and drop_unseen:
        out = out.select_points([k for j, k in enumerate(out.numbers) if j not in never])
        q, pos, rows = out.q, out.measured, out.rows
    elif never:  # every fit would be singular in it: named by the file's numbers and columns
        numbers = [out.numbers[j] for j in never]
        cols = dict(zip(point_numbers_of(columns), columns))
        raise DataError(
            f"{src}: point(s) {', '.join(map(str, numbers))} ({'; '.join(', '.join(cols[k]) for k in numbers)}) "
            "empty in every row; leave them out (--points)",
            option="points",
        )
    mixed_units(q, pos, robot, rows, src, jcols, out.point_numbers)
    return out


def write_measurements(
    path, q, measured, *, position_only: bool = False, joint_names=None, robot: Robot | None = None
) -> None:
    """Write ``q`` ``(K, n)`` (rad / mm) and ``measured`` — poses ``(K, 4, 4)``, positions
    ``(K, 3)`` or points ``(K, M, 3)`` (mm) — as a measurement CSV, atomically.

    Values are written in mm and rad, or with ``robot`` in its units and with its joint names (as
    :func:`read_measurements` reads a file for it by default: a URDF robot's metres), with
    ``repr`` precision (in mm and rad they read back bit-identically; an orientation goes through a
    quaternion, exact to ~1e-16, written with ``qw >= 0``). With ``position_only`` only a pose's
    translation is written. The caller's arrays are not modified.
    """
    from scipy.spatial.transform import Rotation

    q = np.array(q, dtype=np.float64, copy=True)
    meas = np.array(measured, dtype=np.float64, copy=True)
    K = q.shape[0] if q.ndim == 2 else -1
    if meas.shape == (K, 3):
        meas = meas[:, None]
    if q.ndim != 2 or not (meas.shape == (K, 4, 4) or (meas.ndim == 3 and meas.shape[0] == K and meas.shape[2] == 3)):
        raise DataError(
            f"write_measurements: q must be (K, n) and measured (K, 4, 4), (K, 3) or (K, M, 3) with the "
            f"same K; got q {q.shape}, measured {meas.shape}"
        )
    for name, a in (("q", q), ("measured", meas)):
        if not np.isfinite(a).all():
            raise DataError(f"write_measurements: {name}[{int(np.argwhere(~np.isfinite(a))[0][0])}] is not finite")
    if robot is not None:  # the robot's units, which read_measurements assumes for it
        if q.shape[1] != robot.n_joints:
            raise DataError(f"write_measurements: q has {q.shape[1]} joints, robot {robot.name!r} {robot.n_joints}")
        lu = LENGTH_UNITS[robot.units[0]]
        q = q / robot.joint_scale()
        if meas.shape == (K, 4, 4):
            meas[:, :3, 3] /= lu
        else:
            meas = meas / lu
        joint_names = robot.joint_names if joint_names is None else joint_names
    names = [f"q{j}" for j in range(1, q.shape[1] + 1)] if joint_names is None else list(joint_names)
    pose = meas.shape == (K, 4, 4)
    if pose and position_only:
        meas, pose = meas[:, None, :3, 3], False
    if pose:
        R = meas[:, :3, :3]
        err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2))
        if (err > 1e-6).any() or (np.linalg.det(R) < 0).any():
            k = int(np.argmax(np.where(np.linalg.det(R) < 0, np.inf, err)))
            raise DataError(f"write_measurements: measured[{k}] rotation is not a proper rotation matrix")
        xyzw = Rotation.from_matrix(R).as_quat()
        wxyz = xyzw[:, [3, 0, 1, 2]] * np.where(xyzw[:, 3:] < 0, -1.0, 1.0)
        header = names + list(POSITION_COLUMNS) + list(QUAT_COLUMNS)
        table = np.concatenate([q, meas[:, :3, 3], wxyz], axis=1)
    else:
        M = meas.shape[1]
        header = names + (list(POSITION_COLUMNS) if M == 1 else [f"{a}{j}" for j in range(1, M + 1) for a in "xyz"])
        table = np.concatenate([q, meas.reshape(K, 3 * M)], axis=1)
    text = ",".join(header) + "\n" + "".join(",".join(repr(float(v)) for v in row) + "\n" for row in table)
    write_atomic(path, text)
