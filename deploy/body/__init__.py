"""Body backends: the robot's 29 joints + pelvis IMU behind one small interface (deploy.body.base.Body)."""

from deploy.body.base import Body, BodyState
from deploy.body.simulated import SimulatedBody

__all__ = ["Body", "BodyState", "SimulatedBody"]
