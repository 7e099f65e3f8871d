"""URDF files -> joint-frame :class:`jaxcal.Robot` and back, through yourdfpy (meshes are never
loaded).

Reading takes the serial chain from a base link to a tip link: revolute, continuous and
prismatic joints become the robot's joints, each fixed joint is folded into the next movable
joint's origin (the ones after the last, into the tool). Lengths are metres in the file and
millimetres inside.

Writing keeps the nominal file whole where one is given and changes only the chain's movable
joints' ``<origin>``: the calibrated link ``O_i E_i M_i(offset_i)`` equals
``P origin_j E_i M_i(offset_i)``, with ``P`` the fixed joints before it, so the correction and
the offset (a turn about, or shift along, the axis) fold into the joint's own origin. The root
stays the file's root, and three kinds of link are added, fixed joints only:

* ``jaxcal_measurement_frame`` under the chain's base link, at the inverse of the base frame:
  the frame the data were measured in, wherever the base link sits in the tree;
* ``jaxcal_tool`` under the chain's tip link (the calibrated tool frame; identity when it did
  not change);
* ``jaxcal_point<J>`` under ``jaxcal_tool``: the measured points, ``J`` each one's number in
  the data file (``jaxcal_point1`` and ``jaxcal_point3`` for a fit to its points 1 and 3,
  which ``<jaxcal_point_numbers numbers="1 3"/>`` records).

These links are the file's record of its chain: reading a file that has them takes the chain
from the measurement frame's parent to ``jaxcal_tool`` with no link options (options given must
name that chain), and any URDF parser's transform from ``jaxcal_measurement_frame`` to
``jaxcal_point<J>`` is what was measured of point ``J``. Files of the earlier layout (the measurement frame as
the root, above the base link; ``jaxcal_tool`` only where the tool changed) read the same way.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path

import numpy as np

from .._io import write_atomic
from ..errors import RobotFileError
from ..lie import so3_exp
from ._robot import DEFAULT_LIMITS, Robot

M_TO_MM = 1000.0
MEASUREMENT_FRAME = "jaxcal_measurement_frame"
RANGE = "jaxcal_training_range"
"""Element of a calibrated file holding the range of a joint's values the model was fitted on."""
COMPLIANCE = "jaxcal_compliance"
"""Element of a calibrated file holding a joint's compliance (:attr:`jaxcal.Robot.compliance`,
in rad per metre of gravity moment arm) and the moment arm at which its origin holds
(:attr:`jaxcal.Robot.moment_ref`, m; 0 when not given)."""
POINT_NUMBERS = "jaxcal_point_numbers"
"""Element of a calibrated file holding the data file's number of each measured point (files
without it, of an earlier layout, do not say which of the data's points they were fitted on)."""
TOOL_LINK = "jaxcal_tool"
POINT_LINK = "jaxcal_point"
MOVABLE = {"revolute": "R", "continuous": "R", "prismatic": "P"}


def _yourdfpy():
    try:
        import yourdfpy
    except ImportError:  # an optional dependency: DH robots need none of it
        raise RobotFileError("URDF files need yourdfpy: pip install yourdfpy") from None
    return yourdfpy


def _parse(path: Path):
    yourdfpy = _yourdfpy()
    if not path.exists():
        raise RobotFileError(f"robot file not found: {path}")
    from lxml import etree  # yourdfpy's XML library

    try:  # strictly first: yourdfpy recovers from broken XML, dropping what follows the break
        tree = etree.parse(str(path))
    except etree.XMLSyntaxError as e:
        raise RobotFileError(f"{path}: not a readable URDF: the XML is broken: {e}") from None
    except OSError as e:
        raise RobotFileError(f"{path}: cannot be read: {e}") from None
    _check_numbers(tree, path)
    try:
        urdf = yourdfpy.URDF.load(
            str(path),
            build_scene_graph=False,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
        )
    except KeyError as e:  # a required attribute missing: yourdfpy looks it up by name
        raise RobotFileError(f"{path}: not a readable URDF: a required attribute {e} is missing") from None
    except Exception as e:  # yourdfpy raises lxml and its own errors: one message naming the file
        raise RobotFileError(f"{path}: not a readable URDF: {e}") from None
    if urdf.robot is None or not urdf.robot.joints:
        raise RobotFileError(f"{path}: the URDF has no joints")
    names = [j.name for j in urdf.robot.joints]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:  # a corrected origin written back by name would land on the wrong joint
        raise RobotFileError(f"{path}: joint name(s) {', '.join(map(repr, twice))} used twice; URDF names are unique")
    return urdf.robot


NUMBERS = {"origin": {"xyz": 3, "rpy": 3}, "axis": {"xyz": 3}, "limit": {"lower": 1, "upper": 1}}
"""A joint's numeric attributes jaxcal reads, and how many numbers each holds (finite, but a
limit's)."""


def _check_numbers(tree, path: Path) -> None:
    """Refuse a joint's numeric attribute that is not its count of numbers, naming the joint,
    the element and the line (yourdfpy's own error names none): a xacro file not expanded
    (``${...}``, ``$(...)``), a decimal comma, two numbers for three."""
    for joint in tree.getroot().findall("joint"):  # the robot's own: <gazebo> and others nest theirs
        for tag, attrs in NUMBERS.items():
            if tag != "origin" and joint.get("type") == "fixed":  # a fixed joint's axis and limits: unread
                continue
            for el in joint.findall(tag):
                for attr, count in attrs.items():
                    text = el.get(attr)
                    if text is None:
                        continue
                    where = f"{path}: line {el.sourceline}: joint {joint.get('name')!r}, <{tag} {attr}={text!r}>"
                    if "$" in text:
                        raise RobotFileError(f"{where}: a xacro expression; expand the file first (xacro F > F.urdf)")
                    try:
                        values = [float(v) for v in text.split()]
                    except ValueError:
                        raise RobotFileError(f"{where}: not {count} number(s) (a decimal point, spaces)") from None
                    if len(values) != count:
                        raise RobotFileError(f"{where}: {len(values)} number(s), not {count}")
                    if tag != "limit" and not np.all(np.isfinite(values)):  # a limit may be infinite: said later
                        raise RobotFileError(f"{where}: not finite")


def _mm(T) -> np.ndarray:
    T = np.eye(4) if T is None else np.array(T, dtype=np.float64)
    T[:3, 3] *= M_TO_MM
    return T


def _is_ours(link: str) -> bool:
    """A link jaxcal adds to a written model (never part of a robot's chain)."""
    return link in (MEASUREMENT_FRAME, TOOL_LINK) or re.fullmatch(POINT_LINK + r"\d+", link) is not None


def _tree(doc, source: str) -> dict:
    """``{child link: joint}``, refusing what is not a tree: a joint between links the file does
    not declare, a link with two parents, joints that close a loop."""
    declared = {lk.name for lk in doc.links}
    by_child = {}
    for j in doc.joints:
        for role, link in (("parent", j.parent), ("child", j.child)):
            if link not in declared:
                raise RobotFileError(f"{source}: joint {j.name!r}: its {role} link {link!r} is no <link> in the file")
        if j.child in by_child:
            raise RobotFileError(
                f"{source}: link {j.child!r} is the child of two joints ({by_child[j.child].name!r}, {j.name!r}); "
                "a URDF is a tree"
            )
        by_child[j.child] = j
    rooted: set[str] = set()  # links shown to reach a root: each link is walked past once
    for start in by_child:  # up from every link: a tree reaches a root without meeting a link twice
        met, link = {start: 0}, start
        while link in by_child and link not in rooted:
            link = by_child[link].parent
            if link in met:
                loop = ", ".join(repr(by_child[lk].name) for lk in list(met)[met[link] :])
                raise RobotFileError(f"{source}: joints {loop} close a loop; a URDF is a tree")
            met[link] = len(met)
        rooted.update(met)
    return by_child


def _chain(doc, source: str, base_link: str | None, tip_link: str | None):
    """The joints from ``base_link`` to ``tip_link`` (defaults: the root, the one leaf below it
    that jaxcal did not add)."""
    by_child = _tree(doc, source)
    parents = {j.parent for j in doc.joints}
    links = {lk.name for lk in doc.links} | parents | set(by_child)
    for what, name in (("base_link", base_link), ("tip_link", tip_link)):
        if name is not None and name not in links:
            raise RobotFileError(
                f"{source}: no link named {name!r} ({what}); links: {', '.join(sorted(links))}", option=what
            )
    if base_link is None:
        roots = sorted(links - set(by_child))
        if len(roots) != 1:
            raise RobotFileError(
                f"{source}: {len(roots)} root links ({', '.join(roots)}); choose one (base_link)", option="base_link"
            )
        base_link = roots[0]
    if tip_link is None:
        below, todo = set(), [base_link]
        while todo:
            link = todo.pop()
            kids = [j.child for j in doc.joints if j.parent == link and j.child not in below]
            below.update(kids)
            todo += kids
        inner = {j.parent for j in doc.joints if not _is_ours(j.child)}
        leaves = sorted(lk for lk in below if lk not in inner and not _is_ours(lk))
        if len(leaves) != 1:
            raise RobotFileError(
                f"{source}: {len(leaves)} tip links below {base_link!r} ({', '.join(leaves) or 'none'}); "
                "choose one (tip_link)",
                option="tip_link",
            )
        tip_link = leaves[0]
    path, link = [], tip_link
    while link != base_link:
        if link not in by_child or len(path) > len(doc.joints):  # above the root, or round a loop
            raise RobotFileError(
                f"{source}: {tip_link!r} (tip_link) is not below {base_link!r} (base_link)", option="tip_link"
            )
        path.append(by_child[link])
        link = by_child[link].parent
    return path[::-1], base_link, tip_link


def _record(doc):
    """``(base link, tip link, base frame (mm))`` of a model jaxcal wrote, from its added links
    (module docstring); ``None`` for any other URDF. The tip is ``jaxcal_tool``'s parent, or the
    points' parent in the earlier layout (``None`` there when it has neither)."""
    by_child = {j.child: j for j in doc.joints}
    if MEASUREMENT_FRAME in by_child:  # under the base link
        j = by_child[MEASUREMENT_FRAME]
        base_link, base = j.parent, np.linalg.inv(_mm(j.origin))
    else:  # the earlier layout: the root, above the base link
        below = [j for j in doc.joints if j.parent == MEASUREMENT_FRAME]
        if len(below) != 1:
            return None
        base_link, base = below[0].child, _mm(below[0].origin)
    tip = None
    if TOOL_LINK in by_child:
        tip = by_child[TOOL_LINK].parent
    else:
        tip = next((j.parent for j in doc.joints if re.fullmatch(POINT_LINK + r"\d+", j.child)), None)
    return base_link, tip, base


def _agreed(record, base_link, tip_link, source: str):
    """The recorded chain, checked against the link options given: they may name it (the tip
    as the tip link or as ``jaxcal_tool``), nothing else."""
    rec_base, rec_tip, _ = record
    if base_link is not None and base_link != rec_base:
        raise RobotFileError(
            f"{source} is a calibrated model of the chain from {rec_base!r}; {base_link!r} (base_link) does not "
            "match it: leave the link options out, or calibrate the nominal file for another chain",
            option="base_link",
        )
    if tip_link is not None and rec_tip is not None and tip_link not in (rec_tip, TOOL_LINK):
        raise RobotFileError(
            f"{source} is a calibrated model of the chain from {rec_base!r} to {rec_tip!r}; {tip_link!r} "
            "(tip_link) does not match it: leave the link options out, or calibrate the nominal file for another "
            "chain",
            option="tip_link",
        )
    tip = rec_tip if rec_tip is not None else (None if tip_link == TOOL_LINK else tip_link)
    return rec_base, tip


def calibrated_chain(path) -> tuple[str, str | None] | None:
    """``(base link, tip link)`` of a model jaxcal wrote to ``path`` (the chain it was calibrated
    on), or ``None`` for any other URDF."""
    path = Path(path)
    rec = _record(_parse(path))
    return None if rec is None else rec[:2]


def _movable(j, source: str) -> np.ndarray:
    """The unit axis of a movable joint ``j``, its type and mimic checked."""
    if j.type not in MOVABLE:
        raise RobotFileError(
            f"{source}: joint {j.name!r} is {j.type}; a serial chain takes revolute, continuous, prismatic and "
            "fixed joints"
        )
    if j.mimic is not None:
        raise RobotFileError(f"{source}: joint {j.name!r} mimics another joint; not supported in a chain")
    axis = np.array([1.0, 0.0, 0.0]) if j.axis is None else np.asarray(j.axis, dtype=np.float64).reshape(-1)
    n = np.linalg.norm(axis)
    if not (np.isfinite(n) and n > 0):
        raise RobotFileError(f"{source}: joint {j.name!r} has axis {axis.tolist()}; a movable joint needs a direction")
    if j.type == "prismatic" and abs(n - 1.0) > 1e-6:  # readers differ on whether it moves q or |axis| q
        raise RobotFileError(
            f"{source}: prismatic joint {j.name!r} has axis {axis.tolist()} of length {n:.6g}; URDF axes are unit "
            f"vectors, and readers differ on how far such a joint moves; write the unit axis"
        )
    return axis / n


def _limits(j, kind: str, source: str) -> tuple[list[float], bool]:
    """A movable joint's ``[lower, upper]`` (rad, mm) and whether the file gives them:
    :data:`DEFAULT_LIMITS` for a joint without bounds, URDF's default 0 for a bound not given;
    finite and increasing. A continuous joint's bounds are read only when the file gives both,
    increasing: they say how far its readings run (several turns), which the unit checks and pose
    design then take. A prismatic joint must give limits in URDF: its defaults read as none."""
    lim = j.limit
    if lim is None or (lim.lower is None and lim.upper is None):
        return list(DEFAULT_LIMITS[kind]), False
    if j.type == "continuous":
        lower, upper = (float("nan") if v is None else float(v) for v in (lim.lower, lim.upper))
        if not (np.isfinite(lower) and np.isfinite(upper) and lower < upper):
            return list(DEFAULT_LIMITS[kind]), False
    lower, upper = (0.0 if v is None else float(v) for v in (lim.lower, lim.upper))
    if not (np.isfinite(lower) and np.isfinite(upper)):
        raise RobotFileError(
            f"{source}: joint {j.name!r} has limits lower {lower} and upper {upper}; give finite limits, or make it "
            f"continuous if it has none"
        )
    if not lower < upper:
        raise RobotFileError(
            f"{source}: joint {j.name!r} has limits lower {lower} "
            + (
                "= upper: it cannot move; if the file means no limit, make it continuous or give its range"
                if lower == upper
                else f"> upper {upper}"
            )
            + ("" if lim.lower is not None and lim.upper is not None else " (a bound not given is 0 in URDF)")
        )
    scale = 1.0 if kind == "R" else M_TO_MM
    out = [lower * scale, upper * scale]
    return out, kind == "R" or out != list(DEFAULT_LIMITS[kind])


def read_urdf(path, *, base_link: str | None = None, tip_link: str | None = None):
    """``(robot, points)``: the joint-frame robot of the chain from ``base_link`` to
    ``tip_link``, and the measured points (mm, tool frame) a calibrated file carries (``None``
    when it has none). A calibrated file's own chain needs no link options (module docstring)."""
    path = Path(path)
    source = str(path)
    doc = _parse(path)
    base = np.eye(4)
    record = _record(doc)
    if record is not None:
        base_link, tip_link = _agreed(record, base_link, tip_link, source)
        base = record[2]
        if tip_link is not None and any(j.child == TOOL_LINK and j.parent == tip_link for j in doc.joints):
            tip_link = TOOL_LINK
    joints, base_link, tip_link = _chain(doc, source, base_link, tip_link)
    origins, axes, types, names, limits, given = [], [], [], [], [], []
    pending = np.eye(4)
    for j in joints:
        T = _mm(j.origin)
        if j.type == "fixed":
            pending = pending @ T
            continue
        axes.append(_movable(j, source))
        kind = MOVABLE[j.type]
        origins.append(pending @ T)
        pending = np.eye(4)
        lim, has = _limits(j, kind, source)
        limits.append(lim)
        given.append(has)
        types.append(kind)
        names.append(j.name)
    if not types:
        raise RobotFileError(f"{source}: no movable joint between {base_link!r} and {tip_link!r}")
    compliance, moment_ref = _compliance(path, names)
    robot = Robot(
        None,
        convention="joint",
        compliance=compliance,
        moment_ref=moment_ref,
        origins=np.stack(origins),
        axes=np.stack(axes),
        joint_types=types,
        base=base,
        tool=pending,
        q_limits=np.array(limits),
        limits_set=given,
        name=doc.name or path.stem,
        joint_names=names,
        units=("m", "rad"),
    )
    pts = sorted(
        ((int(m.group(1)), j) for j in doc.joints if (m := re.fullmatch(POINT_LINK + r"(\d+)", j.child))),
        key=lambda t: t[0],
    )
    pts = [j for _, j in pts if j.parent == tip_link]
    points = np.stack([_mm(j.origin)[:3, 3] for j in pts]) if pts else None
    return robot, points


def _compliance(path: Path, names: list[str]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The chain's joint compliances (rad/mm) and reference moments (mm) from the file's
    ``<jaxcal_compliance>`` elements, ``None`` without any (moments: without any given)."""
    from lxml import etree  # yourdfpy's XML library

    found, refs = {}, {}
    for el in etree.parse(str(path)).getroot().iter(COMPLIANCE):
        nm = el.get("joint")
        for key, into, scale in (("rad_per_m", found, 1 / M_TO_MM), ("reference_moment_m", refs, M_TO_MM)):
            v = el.get(key)
            if v is None and into is refs:
                continue
            try:
                into[nm] = float(v) * scale
            except (TypeError, ValueError):
                raise RobotFileError(f"{path}: <{COMPLIANCE} joint={nm!r}> needs a number {key}, got {v!r}") from None
            if not np.isfinite(into[nm]):
                raise RobotFileError(f"{path}: <{COMPLIANCE} joint={nm!r}> {key} is not finite ({v!r})")
    if not found:
        return None, None
    c = np.array([found.get(nm, 0.0) for nm in names])
    return c, (np.array([refs.get(nm, 0.0) for nm in names]) if refs else None)


def _folded(robot: Robot, i: int) -> np.ndarray:
    """``E_i M_i(offset_i)`` of joint ``i`` (mm): what its origin is right-multiplied by."""
    p = np.array(robot.dh[i])
    a = np.asarray(robot.axes)[i]
    E = np.eye(4)
    E[:3, :3] = so3_exp(p[4:7])
    E[:3, 3] = p[1:4]
    M = np.eye(4)
    if robot.joint_types[i] == "R":
        M[:3, :3] = so3_exp(a * p[0])
    else:
        M[:3, 3] = a * p[0]
    return E @ M


def _m(T) -> np.ndarray:
    T = np.array(T, dtype=np.float64)
    T[:3, 3] /= M_TO_MM
    return T


def movable_joints_urdf(path, above: str | None = None) -> dict[str, str]:
    """The movable joints of the file between its root and the link ``above`` (the chain's base
    link: what moves it moves the whole chain): name -> ``"R"`` or ``"P"``; none for the root."""
    path = Path(path)
    doc = _parse(path)
    by_child, out, link = _tree(doc, str(path)), {}, above
    while link in by_child and len(out) <= len(doc.joints):
        j = by_child[link]
        if j.type in MOVABLE:
            out[j.name] = MOVABLE[j.type]
        link = j.parent
    return out


def training_ranges_urdf(path) -> dict | None:
    """The ``<jaxcal_training_range>`` elements of a calibrated file (joint name -> ``(lowest,
    highest)``, mm and rad), or ``None``."""
    from lxml import etree  # yourdfpy's XML library

    out = {}
    for el in etree.parse(str(path)).getroot().iter(RANGE):
        try:
            scale = M_TO_MM if el.get("unit") == "m" else 1.0
            out[el.get("joint")] = (float(el.get("lower")) * scale, float(el.get("upper")) * scale)
        except (TypeError, ValueError):
            raise RobotFileError(f"{path}: <{RANGE} joint={el.get('joint')!r}> needs numbers lower, upper") from None
    return out or None


def point_numbers_urdf(path) -> tuple[int, ...] | None:
    """The data file's number of each measured point a calibrated file holds, in the order
    :func:`read_urdf` reads the points (by their links' numbers, which are these), where its
    ``<jaxcal_point_numbers>`` says the links are so named; else ``None``."""
    from lxml import etree  # yourdfpy's XML library

    for el in etree.parse(str(path)).getroot().iter(POINT_NUMBERS):
        text = (el.get("numbers") or "").split()
        if not text or not all(re.fullmatch(r"[0-9]+", t) and int(t) >= 1 for t in text) or len(set(text)) != len(text):
            raise RobotFileError(f"{path}: <{POINT_NUMBERS} numbers=...> needs distinct numbers 1, 2, ...")
        return tuple(sorted(int(t) for t in text))
    return None


def urdf_text(
    robot: Robot,
    *,
    points=None,
    template=None,
    base_link=None,
    tip_link=None,
    comment: dict | None = None,
    training_ranges: dict | None = None,
    point_numbers=None,
) -> str:
    """The URDF of a joint-frame ``robot`` (see the module docstring): the ``template`` file it
    was read from (with the same ``base_link`` and ``tip_link``), every element kept as it was
    (mimic joints, safety limits, transmissions, ros2_control, meshes) but the chain joints'
    origins and axes, which carry the corrections; or a minimal chain of its own without one."""
    if robot.load is not None and robot.compliance is not None and np.any(np.asarray(robot.compliance) != 0):
        raise RobotFileError(
            "this robot's compliances weigh a point that is not its tool origin (its load: a measured point folded "
            "into its tool, as in a one-point --out-robot file), which a URDF cannot hold; write the calibration's "
            "model with its point instead: --out-model with a .urdf path in the calibrate command, or "
            "jaxcal.save_model(result.model, path) (a DH arm's robot through jaxcal.to_joint first)"
        )
    yourdfpy = _yourdfpy()
    from lxml import etree  # yourdfpy's XML library

    if robot.convention != "joint":
        raise RobotFileError("only joint-frame robots are written as URDF (jaxcal.kinematics.to_joint converts DH)")
    if template is not None:
        doc = copy.deepcopy(_parse(Path(template)))  # the chain and the origins, as read_urdf reads them
        record = _record(doc)
        if record is not None:  # a calibrated file calibrated again: its chain, its added links replaced
            base_link, tip_link = _agreed(record, base_link, tip_link, str(template))
            doc.links = [lk for lk in doc.links if not _is_ours(lk.name)]
            doc.joints = [j for j in doc.joints if not (_is_ours(j.child) or _is_ours(j.parent))]
        by_name = {j.name: j for j in doc.joints}
        missing = [nm for nm in robot.joint_names if nm not in by_name]
        if missing:
            raise RobotFileError(f"{template}: no joint named {', '.join(missing)}")
        base_link, tip_link = _chain(doc, str(template), base_link, tip_link)[1:]
        # the nominal tool is the template's fixed joints after the last movable one
        nominal_tool = _tool_of(doc, robot.joint_names[-1], tip_link)
        root = etree.parse(str(template), etree.XMLParser(remove_blank_text=True)).getroot()
        _drop_ours(root)
        elements = {el.get("name"): el for el in root.findall("joint")}
        for i, nm in enumerate(robot.joint_names):
            # a joint the calibration left as it was keeps the file's own text
            if np.any(np.asarray(robot.dh[i]) != 0.0):
                _set(elements[nm], "origin", _mm(by_name[nm].origin) @ _folded(robot, i))
            # unit, as read: every reader then turns it the same way
            axis = None if by_name[nm].axis is None else np.asarray(by_name[nm].axis, float)
            if axis is None or abs(np.linalg.norm(axis) - 1.0) > 1e-12:
                _set(elements[nm], "axis", np.asarray(robot.axes)[i])
    else:
        doc = yourdfpy.Robot(name=robot.name)
        parent = base_link or "base_link"  # the chain's first frame, as the caller names it
        doc.links.append(yourdfpy.Link(name=parent))
        lim, given = np.asarray(robot.q_limits), robot.limits_given()
        for i, nm in enumerate(robot.joint_names):
            child = f"link_{i + 1}"
            doc.links.append(yourdfpy.Link(name=child))
            scale = 1.0 if robot.joint_types[i] == "R" else 1.0 / M_TO_MM
            doc.joints.append(
                yourdfpy.Joint(
                    name=nm,
                    # a revolute joint given no limits has none here either (its defaults are a
                    # sampling range, not the arm's)
                    type=("revolute" if given[i] else "continuous") if robot.joint_types[i] == "R" else "prismatic",
                    parent=parent,
                    child=child,
                    origin=_m(np.asarray(robot.origins)[i] @ _folded(robot, i)),
                    axis=np.asarray(robot.axes)[i],
                    limit=yourdfpy.Limit(effort=0.0, velocity=0.0, lower=lim[i, 0] * scale, upper=lim[i, 1] * scale)
                    if given[i] or robot.joint_types[i] == "P"
                    else yourdfpy.Limit(effort=0.0, velocity=0.0),
                )
            )
            parent = child
        base_link, tip_link, nominal_tool = doc.links[0].name, parent, np.eye(4)
        root = yourdfpy.URDF(robot=doc, build_scene_graph=False, load_meshes=False).write_xml().getroot()

    def fixed(parent, child, T):
        etree.SubElement(root, "link", name=child)
        j = etree.SubElement(root, "joint", name=child + "_joint", type="fixed")
        etree.SubElement(j, "parent", link=parent)
        etree.SubElement(j, "child", link=child)
        _set(j, "origin", T)

    # the record (module docstring): measurement frame under the base link, tool under the tip
    fixed(base_link, MEASUREMENT_FRAME, np.linalg.inv(np.asarray(robot.base)))
    tool = np.linalg.solve(nominal_tool, np.asarray(robot.tool))
    fixed(tip_link, TOOL_LINK, np.eye(4) if np.allclose(tool, np.eye(4), atol=1e-12, rtol=0) else tool)
    pts = np.zeros((0, 3)) if points is None else np.asarray(points)
    # each point's link is named by its number in the data file, so that a subset reads back as itself
    for k, p in zip(range(1, len(pts) + 1) if point_numbers is None else point_numbers, pts):
        T = np.eye(4)
        T[:3, 3] = p
        fixed(TOOL_LINK, f"{POINT_LINK}{k}", T)
    if point_numbers is not None and len(pts):
        root.append(etree.Element(POINT_NUMBERS, numbers=" ".join(str(int(j)) for j in point_numbers)))
    if robot.compliance is not None:  # not URDF's: an element of jaxcal's own, other readers skip it
        refs = np.zeros(robot.n_joints) if robot.moment_ref is None else np.asarray(robot.moment_ref)
        for nm, c, m in zip(robot.joint_names, np.asarray(robot.compliance), refs):
            ref = {} if robot.moment_ref is None else {"reference_moment_m": repr(float(m) / M_TO_MM)}
            root.append(etree.Element(COMPLIANCE, joint=nm, rad_per_m=repr(float(c) * M_TO_MM), **ref))
    kinds = dict(zip(robot.joint_names, robot.joint_types))
    for nm, (lo, hi) in (training_ranges or {}).items():  # metres and radians, as the file's
        s = 1.0 if kinds.get(nm) == "R" else 1.0 / M_TO_MM
        unit = "rad" if kinds.get(nm) == "R" else "m"
        root.append(etree.Element(RANGE, joint=nm, lower=repr(lo * s), upper=repr(hi * s), unit=unit))
    if (
        robot.compliance is not None
        and np.any(np.asarray(robot.compliance) != 0)
        and "compliance" not in (comment or {})
    ):
        # whoever writes it: other readers skip the elements, and the file says so at its top
        comment = dict(comment or {}) | {
            "compliance": "in <jaxcal_compliance> elements, which only jaxcal reads; other URDF readers apply "
            "the rigid geometry only"
        }
    note = "; ".join(f"{k}: {v}" for k, v in comment.items()).replace("--", "- -") if comment else None
    etree.indent(root, space="  ")
    return _serialised(root, note)


NOTE = "jaxcal: "
"""How the comment a calibration writes above the robot element begins (replaced when written again)."""


def _drop_ours(root) -> None:
    """Remove what an earlier calibration added to the file: its links, their joints and its own
    elements."""
    for el in list(root):
        ours = (
            el.tag in (COMPLIANCE, RANGE, POINT_NUMBERS)
            or (el.tag == "link" and _is_ours(el.get("name", "")))
            or (el.tag == "joint" and any(_is_ours(c.get("link", "")) for c in el if c.tag in ("parent", "child")))
        )
        if ours:
            root.remove(el)


def _serialised(root, comment: str | None) -> str:
    """The document: the comments beside the robot element kept (a licence, xacro's note) but an
    earlier calibration's, then ``comment``, then the robot element."""
    from lxml import etree

    def kept(nodes):
        return [
            etree.tostring(n, encoding="unicode", with_tail=False) + "\n"
            for n in nodes
            if n.tag is etree.Comment
            and not (n.text or "").lstrip().startswith(NOTE.strip())
            and "heldout_rms_mm:" not in (n.text or "")  # the earlier comment, before it began with NOTE
        ]

    before = kept(reversed(list(root.itersiblings(preceding=True))))
    after = kept(root.itersiblings())
    ours = [] if comment is None else [etree.tostring(etree.Comment(f" {NOTE}{comment} "), encoding="unicode") + "\n"]
    body = etree.tostring(root, pretty_print=True, encoding="unicode", with_tail=False) + "\n"
    return '<?xml version="1.0" encoding="utf-8"?>\n' + "".join(before + ours) + body + "".join(after)


def _set(element, tag: str, value) -> None:
    """Set (or add) ``<origin xyz rpy>`` from a transform (mm) or ``<axis xyz>`` from a vector."""
    from lxml import etree
    from yourdfpy.urdf import tra  # the conversion yourdfpy reads rpy with

    el = element.find(tag)
    if el is None:
        el = etree.SubElement(element, tag)
    if tag == "origin":
        T = _m(value)
        el.set("xyz", " ".join(repr(float(v)) for v in T[:3, 3]))
        el.set("rpy", " ".join(repr(float(v)) for v in tra.euler_from_matrix(T)))
    else:
        el.set("xyz", " ".join(repr(float(v)) for v in value))


def _tool_of(doc, last_joint: str, tip_link: str) -> np.ndarray:
    """The product of the fixed joints from the last movable joint's child to ``tip_link`` (mm):
    the nominal tool as :func:`read_urdf` builds it."""
    by_child = {j.child: j for j in doc.joints}
    T, link = np.eye(4), tip_link
    while by_child[link].name != last_joint:
        T = _mm(by_child[link].origin) @ T
        link = by_child[link].parent
    return T


def save_urdf(
    robot: Robot,
    path,
    *,
    points=None,
    template=None,
    base_link=None,
    tip_link=None,
    comment=None,
    training_ranges=None,
    point_numbers=None,
) -> None:
    """Write :func:`urdf_text` atomically."""
    text = urdf_text(
        robot,
        points=points,
        template=template,
        base_link=base_link,
        tip_link=tip_link,
        comment=comment,
        training_ranges=training_ranges,
        point_numbers=point_numbers,
    )
    write_atomic(path, text)
