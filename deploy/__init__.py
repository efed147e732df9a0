"""Onboard runtime for robot-hoi policies on the Unitree G1 with two Inspire hands.

Runs on the robot's computer with only numpy, onnxruntime, pyserial, python-can, pymodbus, pyyaml and rich
installed: nothing in this package imports torch, mujoco or robot_hoi. The ONNX policy file is the contract
(deploy.contract); the loop (deploy.loop) feeds it observations (deploy.observations) built from the body
(deploy.body), the pose tracker (deploy.tracking) and the hands (deploy.hands) through a safety state machine
(deploy.safety).
"""

__all__ = ["__version__"]

__version__ = "0.1.0"
