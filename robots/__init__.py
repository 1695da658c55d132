"""Robot descriptions (Pinocchio models + actuator data) and the MPC's linearisation."""

from robots.linearize import LinearArm, linearize
from robots.model import Robot
from robots.registry import ROBOTS, load_robot

__all__ = ["ROBOTS", "LinearArm", "Robot", "linearize", "load_robot"]
