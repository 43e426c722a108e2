"""The robot arm of the cell: a URDF model (Pinocchio), IK, collision checks (coal), joint-space motion (our
seeded RRT-Connect, ruckig), and a simulated joint arm.

- ``config``      ArmConfig (URDF, flange, hand-eye, mount, limits, planning settings)
- ``model``       load_arm -> ArmModel (Pinocchio model with the mount and the camera frame); check_arm for start-up
- ``collision``   CollisionWorld (links vs plate, table, object box, themselves)
- ``ik``          damped least squares IK with joint limits; every branch of a UR-type arm in closed form
- ``closed_form`` ClosedFormIK: the eight IK branches of a UR-type arm (product of exponentials, no iteration)
- ``reach``       ArmReach: plate angle + IK + collisions per view, with the reason
- ``motion``      plan_path (straight or a deterministic RRT-Connect + shortcut), time_path (ruckig)
- ``kinematics``  ArmKinematics: all of it for the Cell
- ``sim_arm``     SimulatedJointArm (a JointArm)

Importing ``devices.arm`` loads no Pinocchio, coal or ruckig (the modules do when used).
"""

from devices.arm.config import ArmConfig
from devices.arm.model import check_arm

__all__ = ["ArmConfig", "check_arm"]
