"""Joint-torque references from a force/torque sensor and the arm's kinematics.

$\\tau = \\tau_\\text{model} + s\\,J(q)^\\top (W - w_0)$: the measured wrench $W$ mapped to the
joints by the geometric Jacobian (DH table in JAX, or a URDF through pinocchio), plus the arm's
own model torque; sample-and-hold wrench streams are used only where a new value arrives, and
the sensor offset $w_0$ is estimated and reported. Configured by the `[data.reference]` table.
"""

from ._builder import (
    WrenchReference as WrenchReference,
    build_wrench_reference as build_wrench_reference,
    joint_torque as joint_torque,
)
from ._checks import reference_checks as reference_checks
from ._dh import (
    CONVENTIONS as CONVENTIONS,
    DHArm as DHArm,
    dh_arm as dh_arm,
    dh_arm_from_table as dh_arm_from_table,
    forward_kinematics as forward_kinematics,
    link_transform as link_transform,
    load_dh_table as load_dh_table,
    rpy_matrix as rpy_matrix,
)
from ._holds import Holds as Holds, detect_holds as detect_holds
from ._jacobian import (
    FRAMES as FRAMES,
    geometric_jacobian as geometric_jacobian,
    jacobian_columns as jacobian_columns,
    jacobians as jacobians,
    tool_rotations as tool_rotations,
)
from ._load import (
    describe_column_reference as describe_column_reference,
    load_referenced as load_referenced,
    load_with_reference as load_with_reference,
)
from ._offset import (
    SensorOffset as SensorOffset,
    fit_offset_with_payload as fit_offset_with_payload,
    no_offset as no_offset,
    offset_from_rest as offset_from_rest,
)
from ._spec import (
    KINDS as KINDS,
    OFFSETS as OFFSETS,
    check_reference as check_reference,
    needed_columns as needed_columns,
)
from ._urdf import UrdfArm as UrdfArm, import_pinocchio as import_pinocchio
