"""The ONNX policy: one onnxruntime session, contract checked on load, one observation row in, actions out."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import onnxruntime as ort

from deploy.contract import INPUT_NAME, OUTPUT_NAME, PolicyContract
from deploy.errors import ContractError, DeployError


def open_session(path: str | os.PathLike):
    """An onnxruntime CPU session with one intra-op thread (lowest jitter on the robot's small CPU)."""
    path = Path(path)
    if not path.is_file():
        raise DeployError(f"{path}: policy file not found")
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.log_severity_level = 3
    try:
        return ort.InferenceSession(str(path), sess_options=options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own Fail/InvalidGraph types
        raise ContractError(f"{path}: not a loadable ONNX model ({type(exc).__name__}: {exc})") from None


class OnnxPolicy:
    """Callable policy: obs (obs_dim,) float -> raw actions (num_actions,) float64."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.session = open_session(self.path)
        self.contract = PolicyContract.from_session(self.session, str(self.path))
        self._input = np.zeros((1, self.contract.obs_dim), dtype=np.float32)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        self._input[0] = obs
        (actions,) = self.session.run([OUTPUT_NAME], {INPUT_NAME: self._input})
        return actions[0].astype(np.float64)
