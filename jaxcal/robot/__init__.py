"""Robot models: a DH table or joint frames (URDF) with base and tool frames, published presets, and robot
files (TOML, URDF, UR kinematics YAML)."""

from ._files import calibrated_chain as calibrated_chain
from ._files import load_robot as load_robot
from ._files import read_movable_joints as read_movable_joints
from ._files import read_point_numbers as read_point_numbers
from ._files import read_robot_file as read_robot_file
from ._files import read_training_ranges as read_training_ranges
from ._files import save_robot as save_robot
from ._presets import PRESETS as PRESETS
from ._presets import preset as preset
from ._robot import ANGLE_UNITS as ANGLE_UNITS
from ._robot import CONVENTIONS as CONVENTIONS
from ._robot import DEFAULT_LIMITS as DEFAULT_LIMITS
from ._robot import DH_NAMES as DH_NAMES
from ._robot import JOINT_FRAME_NAMES as JOINT_FRAME_NAMES
from ._robot import LENGTH_UNITS as LENGTH_UNITS
from ._robot import Robot as Robot
from ._toml import robot_from_dict as robot_from_dict
from ._toml import robot_to_dict as robot_to_dict
from ._ur import UR_BASE as UR_BASE
from ._ur import UR_JOINT_NAMES as UR_JOINT_NAMES
from ._ur import UR_KEYS as UR_KEYS
from ._ur import UR_ORIGINS as UR_ORIGINS
from ._ur import read_ur_kinematics as read_ur_kinematics
from ._urdf import urdf_text as urdf_text
