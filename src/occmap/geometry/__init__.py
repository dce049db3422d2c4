"""Rigid-body geometry: SO(2), SE(2), SO(3), SE(3), Euler angles, quaternions, frames, motion.

Conventions (shared by every function; each module's docstring gives the details):

- float64 arrays; every function broadcasts over leading dimensions, so one call handles one
  pose or a million.
- Rotation matrices act on column vectors; ``T_a_b`` maps frame-b coordinates to frame a.
- Quaternions are scalar first ``(w, x, y, z)``; ROS order via :func:`quat_from_xyzw`.
- Euler angles are Z-Y-X: ``R = Rz(yaw) Ry(pitch) Rx(roll)``.
- Twists are ``(ρ, φ)``: translation part first.
- Bad input raises a subclass of :class:`occmap.errors.OccmapError` naming the element.
"""

from . import motion, so3
from .euler import euler_zyx_to_matrix, matrix_to_euler_zyx
from .frames import FrameTree
from .motion import (
    OdometryMotionModel,
    apply_odometry,
    bicycle_step,
    diff_drive_step,
    odometry_delta,
    unicycle_step,
)
from .quaternion import (
    axis_angle_to_quat,
    matrix_to_quat,
    quat_conjugate,
    quat_from_xyzw,
    quat_inverse,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_slerp,
    quat_to_axis_angle,
    quat_to_matrix,
    quat_to_xyzw,
)
from .se2 import SE2, compose_poses, relative_poses, se2_from_matrix, se2_matrix
from .se3 import SE3, compose_transforms, exp_se3, invert_transform, log_se3, make_transform, transform_points
from .so2 import SO2, rot2, so2_angle, wrap_angle, wrap_angle_one
from .so3 import (
    SO3,
    axis_angle_to_matrix,
    exp_so3,
    hat,
    is_rotation,
    log_so3,
    matrix_to_axis_angle,
    nearest_rotation,
    random_rotations,
    rot_x,
    rot_y,
    rot_z,
    vee,
)

__all__ = sorted([
    *motion.__all__,
    *so3.__all__,
    "FrameTree",
    "SE2",
    "SE3",
    "SO2",
    "axis_angle_to_quat",
    "compose_poses",
    "compose_transforms",
    "euler_zyx_to_matrix",
    "exp_se3",
    "invert_transform",
    "log_se3",
    "make_transform",
    "matrix_to_euler_zyx",
    "matrix_to_quat",
    "quat_conjugate",
    "quat_from_xyzw",
    "quat_inverse",
    "quat_multiply",
    "quat_normalize",
    "quat_rotate",
    "quat_slerp",
    "quat_to_axis_angle",
    "quat_to_matrix",
    "quat_to_xyzw",
    "relative_poses",
    "rot2",
    "se2_from_matrix",
    "se2_matrix",
    "so2_angle",
    "transform_points",
    "wrap_angle",
    "wrap_angle_one",
])
