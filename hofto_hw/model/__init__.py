"""The arm's dynamic model: RobotModel (pinocchio underneath), friction, identified parameters."""

from hofto_hw.model.friction import FrictionParams
from hofto_hw.model.robot import JointLimits, RobotModel

__all__ = ["FrictionParams", "JointLimits", "RobotModel"]
