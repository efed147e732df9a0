"""Loading the inputs the runtime trusts: embodiment YAML, motion sidecar, dev policy generator."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import onnxruntime as ort
import pytest
import yaml

from deploy.contract import PolicyContract
from deploy.devpolicy import build_dev_policy, main, read_urdf_limits
from deploy.embodiment import load_embodiment
from deploy.errors import DeployError
from deploy.motion import file_sha256, load_motion

from .conftest import EMBODIMENT_YAML


def test_embodiment_yaml_loads():
    emb = load_embodiment(EMBODIMENT_YAML)
    assert emb.name == "g1_inspire" and len(emb.actuators) == 41
    assert emb.actuator_names[:2] == ["left_hip_pitch_joint", "left_hip_roll_joint"]
    assert [c.name for c in emb.hands["right"]][-1] == "thumb_rotate"
    assert emb.control_dt == pytest.approx(1 / 30)
    assert load_embodiment("g1_inspire").path.resolve() == EMBODIMENT_YAML.resolve()


@pytest.mark.parametrize("edit,expected", [
    (lambda r: r.pop("control_dt"), "missing key 'control_dt'"),
    (lambda r: r["actuators"][2].pop("kd"), "actuators[2] (left_hip_yaw_joint) is missing 'kd'"),
    (lambda r: r["actuators"][0].update(kp="stiff"), "actuators[0].kp must be a finite number"),
    (lambda r: r["hands"]["left"]["channels"].pop(), "hands.left.channels must list 6"),
    (lambda r: r["hands"]["right"]["channels"][0].update(joint="nope"), "joint 'nope' is not an actuator"),
])
def test_embodiment_errors_name_file_and_key(tmp_path, edit, expected):
    raw = yaml.safe_load(EMBODIMENT_YAML.read_text())
    edit(raw)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(DeployError) as info:
        load_embodiment(path)
    assert str(path) in str(info.value) and expected in str(info.value)


def test_unknown_embodiment_name():
    with pytest.raises(DeployError, match="no h7_robot.yaml"):
        load_embodiment("h7_robot")


def test_dev_policy_follows_reference_through_onnxruntime(dev_policy):
    contract = PolicyContract.from_onnx(dev_policy)
    motion = load_motion(contract.reference_path(), contract.reference.sha256)
    assert motion.num_frames == 120 and motion.fps == pytest.approx(30.0)
    obs = np.zeros((1, contract.obs_dim), np.float32)
    start = sum(t.size for t in contract.obs_spec[: contract.obs_names.index("ref_joint_pos")])
    ref_q = motion.joint_pos[50]
    obs[0, start:start + 41] = ref_q - contract.default_pose
    (actions,) = ort.InferenceSession(str(dev_policy)).run(["actions"], {"obs": obs})
    np.testing.assert_allclose(contract.action_to_target(actions[0]), ref_q, atol=1e-5)


def test_dev_policy_cli_and_options(tmp_path, capsys):
    assert main(["-o", str(tmp_path / "a.onnx"), "--embodiment", str(EMBODIMENT_YAML), "--keyframes", "0", "5",
                 "--obs", "projected_gravity", "joint_pos", "ref_joint_pos", "--mode", "random"]) == 0
    c = PolicyContract.from_onnx(tmp_path / "a.onnx")
    assert c.keyframes == (0, 5) and c.obs_names == ["projected_gravity", "joint_pos", "ref_joint_pos"]
    assert c.obs_dim == 3 + 41 + 82 and (tmp_path / "a.motion.npz").is_file()
    assert main(["-o", str(tmp_path / "b.onnx"), "--obs", "bogus_term"]) == 2
    assert "unknown observation term" in capsys.readouterr().err
    path = build_dev_policy(tmp_path / "c.onnx", embodiment=EMBODIMENT_YAML, with_reference=False,
                            obs_terms=["joint_pos", "last_action"])
    assert PolicyContract.from_onnx(path).reference is None


def test_limits_from_a_urdf(tmp_path):
    urdf = tmp_path / "r.urdf"
    urdf.write_text('<robot name="r"><joint name="a" type="revolute"><limit lower="-1" upper="2" effort="9" '
                    'velocity="1"/></joint><joint name="f" type="fixed"/></robot>')
    assert read_urdf_limits(urdf) == {"a": (-1.0, 2.0, 9.0)}
    with pytest.raises(DeployError, match="has no joint limits"):
        build_dev_policy(tmp_path / "p.onnx", embodiment=EMBODIMENT_YAML, urdf=urdf)


def _motion_arrays(num=4, links=2, actuators=41):
    return {
        "fps": np.array(30.0), "joint_pos": np.zeros((num, actuators)), "root_pos": np.zeros((num, 3)),
        "root_quat_wxyz": np.tile([1.0, 0, 0, 0], (num, 1)), "link_pos": np.zeros((num, links, 3)),
        "object_pos": np.zeros((num, 3)), "object_quat_wxyz": np.tile([1.0, 0, 0, 0], (num, 1)),
    }


@pytest.mark.parametrize("edit,expected", [
    (lambda a: a.pop("link_pos"), "missing array(s) link_pos"),
    (lambda a: a.update(root_pos=np.zeros((3, 3))), "root_pos has shape (3, 3), expected (T, 3) with T = 4"),
    (lambda a: a.update(object_quat_wxyz=np.zeros((4, 4))), "object_quat_wxyz is not a unit quaternion"),
    (lambda a: a["joint_pos"].__setitem__((1, 1), np.nan), "joint_pos has non-finite values"),
    (lambda a: a.update(fps=np.array([30.0, 30.0])), "fps must be a positive scalar"),
    (lambda a: a.update(root_pos=np.array([["a", "b", "c"]] * 4)), "root_pos must be numeric"),
])
def test_motion_errors(tmp_path, edit, expected):
    arrays = _motion_arrays()
    edit(arrays)
    path = tmp_path / "m.motion.npz"
    np.savez(path, **arrays)
    with pytest.raises(DeployError) as info:
        load_motion(path)
    assert str(path) in str(info.value) and expected in str(info.value)


def test_motion_refuses_pickles_and_junk(tmp_path):
    arrays = _motion_arrays()
    arrays["joint_pos"] = np.array([{"evil": 1}] * 4, dtype=object)
    path = tmp_path / "pickle.motion.npz"
    np.savez(path, **arrays)
    with pytest.raises(DeployError, match="not a readable motion npz"):
        load_motion(path)
    junk = tmp_path / "junk.motion.npz"
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as zf:
        zf.writestr("x.txt", "hello")
    junk.write_bytes(buffer.getvalue()[:20])
    with pytest.raises(DeployError, match="not a readable motion npz"):
        load_motion(junk)


def test_motion_sha_must_match(tmp_path):
    path = tmp_path / "m.motion.npz"
    np.savez(path, **_motion_arrays())
    assert load_motion(path, expected_sha256=file_sha256(path)).num_frames == 4
    with pytest.raises(DeployError, match="sha256 does not match"):
        load_motion(path, expected_sha256="0" * 64)
