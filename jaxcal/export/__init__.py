"""Calibrated models in the forms other tools load: a Universal Robots kinematics file, the DH
table with its changes and standard errors, and a one-page HTML report."""

from ._dh import check_dh as check_dh
from ._dh import dh_rows as dh_rows
from ._dh import dh_table as dh_table
from ._dh import save_dh_table as save_dh_table
from ._report import accuracy_map as accuracy_map
from ._report import report_html as report_html
from ._report import save_report as save_report
from ._ur import check_ur as check_ur
from ._ur import save_ur_kinematics as save_ur_kinematics
from ._ur import ur_kinematics as ur_kinematics
from ._ur import ur_kinematics_text as ur_kinematics_text
