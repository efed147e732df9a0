"""Policy -> ONNX with metadata, verified on the way out.

The graph takes `obs` float32 [batch, obs_dim] and returns `actions` float32 [batch, num_actions] (observation
normalisation baked in; the names are deploy.contract's INPUT_NAME and OUTPUT_NAME). Verification: onnx.checker, ONNX Runtime vs torch within `tolerance` (max abs) on random
and recorded observations, and ORT latency (batch 1, one thread). The file is written atomically.
"""

from __future__ import annotations

import io
import json
import statistics
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch

from deploy.atomic import atomic_write_bytes
from deploy.contract import INPUT_NAME, OUTPUT_NAME
from robot_hoi.errors import UserError

OPSET = 17


@dataclass
class ExportReport:
    path: Path
    max_abs_error_random: float
    max_abs_error_recorded: float | None
    ort_latency_p50_ms: float
    ort_latency_p99_ms: float

    def lines(self) -> list[str]:
        out = [f"wrote {self.path}", f"ORT vs torch max |diff|: random {self.max_abs_error_random:.2e}"
               + ("" if self.max_abs_error_recorded is None else f", recorded {self.max_abs_error_recorded:.2e}"),
               f"ORT latency (batch 1, 1 thread): p50 {self.ort_latency_p50_ms:.3f} ms, "
               f"p99 {self.ort_latency_p99_ms:.3f} ms"]
        return out


def to_onnx_bytes(policy: torch.nn.Module, obs_dim: int, metadata: dict[str, str]) -> bytes:
    policy = policy.eval()
    buffer = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the TorchScript exporter is deprecated but needs no extra packages
        torch.onnx.export(
            policy, (torch.zeros(1, obs_dim),), buffer, input_names=[INPUT_NAME], output_names=[OUTPUT_NAME],
            dynamic_axes={INPUT_NAME: {0: "batch"}, OUTPUT_NAME: {0: "batch"}}, opset_version=OPSET, dynamo=False,
        )
    model = onnx.load_from_string(buffer.getvalue())
    onnx.helper.set_model_props(model, metadata)
    onnx.checker.check_model(model)
    return model.SerializeToString()


def ort_session(data: bytes):
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    return ort.InferenceSession(data, options, providers=["CPUExecutionProvider"])


def compare(policy: torch.nn.Module, session, obs: np.ndarray) -> float:
    with torch.no_grad():
        expected = policy(torch.as_tensor(obs, dtype=torch.float32)).numpy()
    got = session.run([OUTPUT_NAME], {INPUT_NAME: obs.astype(np.float32)})[0]
    return float(np.abs(expected - got).max())


def latency_ms(session, obs_dim: int, runs: int = 300) -> tuple[float, float]:
    x = np.zeros((1, obs_dim), dtype=np.float32)
    for _ in range(20):
        session.run([OUTPUT_NAME], {INPUT_NAME: x})
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        session.run([OUTPUT_NAME], {INPUT_NAME: x})
        times.append(1e3 * (time.perf_counter() - t0))
    times.sort()
    return statistics.median(times), times[int(0.99 * (len(times) - 1))]


def export_policy(policy: torch.nn.Module, obs_dim: int, metadata: dict, out: str | Path,
                  recorded_obs: np.ndarray | None = None, tolerance: float = 1e-4, seed: int = 0) -> ExportReport:
    """Export, verify, then write atomically. Raises UserError (nothing written) when verification fails."""
    encoded = {k: json.dumps(v) for k, v in metadata.items()}  # the contract: every value JSON-encoded
    data = to_onnx_bytes(policy, obs_dim, encoded)
    session = ort_session(data)
    rng = np.random.default_rng(seed)
    err_random = compare(policy, session, rng.normal(size=(1000, obs_dim)).astype(np.float32))
    err_recorded = None
    if recorded_obs is not None and len(recorded_obs):
        err_recorded = compare(policy, session, np.asarray(recorded_obs[:1000], dtype=np.float32))
    worst = max(err_random, err_recorded or 0.0)
    if not np.isfinite(worst) or worst > tolerance:
        raise UserError(f"{out}: ONNX Runtime and torch disagree by {worst:.2e} (> {tolerance:g}); not written")
    p50, p99 = latency_ms(session, obs_dim)
    out = Path(out)
    atomic_write_bytes(out, data)
    return ExportReport(out, err_random, err_recorded, p50, p99)


def check_onnx_file(path: str | Path) -> dict[str, str]:
    """onnx.checker + the signature check; returns the metadata. Clear UserError for a malformed file."""
    path = Path(path)
    try:
        model = onnx.load(str(path))
        onnx.checker.check_model(model)
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    except Exception as exc:  # onnx raises DecodeError / ValidationError with long messages
        raise UserError(f"{path}: not a valid ONNX model ({str(exc).splitlines()[0][:200]})") from None
    inputs = [i.name for i in model.graph.input]
    outputs = [o.name for o in model.graph.output]
    if inputs != [INPUT_NAME] or outputs != [OUTPUT_NAME]:
        raise UserError(f"{path}: expected one input '{INPUT_NAME}' and one output '{OUTPUT_NAME}', "
                        f"found inputs {inputs} and outputs {outputs}")
    return {p.key: p.value for p in model.metadata_props}
