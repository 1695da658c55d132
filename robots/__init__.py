"""Robot descriptions (Pinocchio models + actuator data) and the MPC's linearisation."""

from rhmpc.robots.linearize import LinearArm, linearize
from rhmpc.robots.model import Robot
from rhmpc.robots.registry import ROBOTS, load_robot

__all__ = ["ROBOTS", "LinearArm", "Robot", "linearize", "load_robot"]
