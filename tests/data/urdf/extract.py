"""Extract the corpus URDFs from an example-robot-data wheel (``pip download --no-deps
example-robot-data``), kinematics only: links and joints (origin, axis, limit, mimic) are kept;
meshes, visuals, collisions, inertials, materials, transmissions and comments are dropped.

    python tests/data/urdf/extract.py example_robot_data-6.0.0-0-py3-none-any.whl
"""

import sys
import zipfile
from pathlib import Path

from lxml import etree

ROBOTS = "cmeel.prefix/share/example-robot-data/robots/"
FILES = {  # file: (member of ROBOTS, licence as the package's README states it)
    "panda.urdf": ("panda_description/urdf/panda.urdf", "Apache-2.0"),
    "ur5.urdf": ("ur_description/urdf/ur5_robot.urdf", "BSD"),
    "kinova.urdf": ("kinova_description/robots/kinova.urdf", "BSD"),
    "xarm7.urdf": ("xarm_description/urdf/xarm7.urdf", "BSD-3-Clause"),
    "tiago.urdf": ("tiago_description/robots/tiago.urdf", "Apache-2.0"),
    "so100.urdf": ("so_arm_description/urdf/so100.urdf", "Apache-2.0"),
}
JOINT_PARTS = ("parent", "child", "origin", "axis", "limit", "mimic")


def kinematics(xml: bytes, note: str) -> bytes:
    root = etree.fromstring(xml, etree.XMLParser(remove_comments=True, remove_blank_text=True))
    for el in list(root):
        if el.tag not in ("link", "joint"):
            root.remove(el)
    for link in root.findall("link"):
        for el in list(link):
            link.remove(el)
    for joint in root.findall("joint"):
        for el in list(joint):
            if el.tag not in JOINT_PARTS:
                joint.remove(el)
    root.insert(0, etree.Comment(f" {note} "))
    etree.indent(root, space="  ")
    return etree.tostring(root, xml_declaration=True, encoding="utf-8") + b"\n"


if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    with zipfile.ZipFile(sys.argv[1]) as wheel:
        for name, (member, licence) in FILES.items():
            note = f"example-robot-data 6.0.0, {member} ({licence}); kinematics only (README.md)"
            (here / name).write_bytes(kinematics(wheel.read(ROBOTS + member), note))
        (here / "LICENSE").write_bytes(wheel.read("example_robot_data-6.0.0.dist-info/licenses/LICENSE"))
        (here / "LICENSE-Apache-2.0").write_bytes(wheel.read(ROBOTS + "panda_description/LICENSE"))
