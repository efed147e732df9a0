"""The ONNX contract: parse, round trip, refuse malformed files with a message naming the problem."""

from __future__ import annotations

import json
import shutil

import numpy as np
import onnxruntime as ort
import pytest
import yaml

from deploy.contract import PolicyContract, check_against_embodiment
from deploy.devpolicy import make_contract, onnx_bytes
from deploy.embodiment import load_embodiment
from deploy.errors import ContractError, DeployError

from .conftest import EMBODIMENT_YAML


@pytest.fixture(scope="module")
def contract() -> PolicyContract:
    return make_contract(load_embodiment(EMBODIMENT_YAML), keyframes=(1, 16))


def write_policy(path, metadata: dict[str, str], obs_dim: int, num_actions: int, **names):
    weights = np.zeros((obs_dim, num_actions), np.float32)
    path.write_bytes(onnx_bytes(metadata, weights, np.zeros(num_actions, np.float32), **names))
    return path


def test_dev_policy_parses_with_expected_layout(dev_policy):
    c = PolicyContract.from_onnx(dev_policy)
    assert c.num_actions == 41 and c.num_body == 29
    assert c.actuator_names[0] == "left_hip_pitch_joint" and c.actuator_names[29] == "L_pinky_proximal_joint"
    assert c.actuator_names[35] == "R_pinky_proximal_joint"
    assert c.keyframes == (1, 16)
    sizes = {t.name: t.size for t in c.obs_spec}
    assert sizes["ref_link_pos"] == 3 * len(c.link_names) * 2 and sizes["ref_joint_pos"] == 82
    assert c.obs_dim == sum(sizes.values())
    assert c.reference is not None and c.reference_path().is_file()
    assert c.hand_slice("left") == slice(29, 35) and c.hand_slice("right") == slice(35, 41)
    check_against_embodiment(c, EMBODIMENT_YAML)


def test_metadata_round_trip(contract, tmp_path):
    meta = contract.to_metadata()
    assert all(isinstance(v, str) for v in meta.values())
    assert json.loads(meta["robot_hoi.contract"]) == "1"
    path = write_policy(tmp_path / "p.onnx", meta, contract.obs_dim, contract.num_actions)
    back = PolicyContract.from_onnx(path)
    assert back.to_metadata() == meta
    for key in ("default_pose", "kp", "joint_lower", "effort_limit"):
        np.testing.assert_array_equal(getattr(back, key), getattr(contract, key))
    assert back.hands == contract.hands and back.obs_spec == contract.obs_spec


def test_action_to_target_clips_then_scales(contract):
    action = np.zeros(contract.num_actions)
    action[0], action[1] = 100.0, -0.5
    target = contract.action_to_target(action)
    assert target[0] == pytest.approx(contract.action_offset[0] + contract.action_scale[0] * contract.action_clip)
    assert target[1] == pytest.approx(contract.action_offset[1] - 0.5 * contract.action_scale[1])


def _mutate(meta: dict[str, str], key: str, fn):
    out = dict(meta)
    if fn is None:
        del out[key]
    else:
        out[key] = json.dumps(fn(json.loads(meta[key])))
    return out


MALFORMED = [
    ("missing key", "kp", None, "missing metadata key(s) 'kp'"),
    ("wrong version", "robot_hoi.contract", lambda v: "2", "robot_hoi.contract"),
    ("bad kind", "policy_kind", lambda v: "expert", "policy_kind"),
    ("short list", "kd", lambda v: v[:-1], "'kd' has 40 entries, expected 41"),
    ("nan value", "action_scale", lambda v: v[:3] + ["NaN"] + v[4:], "action_scale"),
    ("infinite default", "default_pose", lambda v: [1e400] + v[1:], "non-finite"),
    ("limits inverted", "joint_lower", lambda v: [10.0] + v[1:], "not below joint_upper"),
    ("default outside limits", "default_pose", lambda v: [-3.0] + v[1:], "outside the joint limits"),
    ("negative kp", "kp", lambda v: [-1.0] + v[1:], "negative"),
    ("zero control_dt", "control_dt", lambda v: 0.0, "control_dt"),
    ("negative keyframe", "keyframes", lambda v: [-1, 16], "keyframes"),
    ("unknown term", "obs_spec", lambda v: v + [{"name": "joint_torque", "size": 0}], "unknown observation term 'joint_torque'"),
    ("teacher term", "obs_spec", lambda v: [{"name": "teacher.body_pos", "size": 3}] + v,
     "a teacher policy cannot run on the robot"),
    ("wrong term size", "obs_spec", lambda v: [{"name": "joint_pos", "size": 40}] + v[1:], "term 'joint_pos' has size 40"),
    ("duplicate term", "obs_spec", lambda v: v + v[:1], "twice"),
    ("hand channel order", "hands", lambda v: {"left": v["left"][::-1], "right": v["right"]}, "Inspire register order"),
    ("hand joint not actuator", "hands",
     lambda v: {"left": [dict(c, joint="foo") if i == 0 else c for i, c in enumerate(v["left"])], "right": v["right"]},
     "joint 'foo'"),
    ("hand open == closed", "hands",
     lambda v: {"left": [dict(c, open_rad=c["closed_rad"]) if i == 2 else c for i, c in enumerate(v["left"])],
                "right": v["right"]}, "open_rad == closed_rad"),
    ("reference path", "reference", lambda v: {"file": "../x.motion.npz", "sha256": "0" * 64}, "bare file name"),
    ("reference sha", "reference", lambda v: {"file": "x.motion.npz", "sha256": "xyz"}, "sha256"),
    ("data license", "data", lambda v: {"clips": []}, "'data'"),
    ("duplicate actuator", "actuator_names", lambda v: [v[1]] + v[1:], "duplicate"),
]


@pytest.mark.parametrize("case,key,fn,expected", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_metadata_is_refused_with_the_problem_named(contract, tmp_path, case, key, fn, expected):
    meta = _mutate(contract.to_metadata(), key, fn)
    path = write_policy(tmp_path / "bad.onnx", meta, contract.obs_dim, contract.num_actions)
    with pytest.raises(ContractError) as info:
        PolicyContract.from_onnx(path)
    message = str(info.value)
    assert str(path) in message
    assert expected in message
    assert info.value.user_error


def test_not_json_is_refused(contract, tmp_path):
    meta = dict(contract.to_metadata(), kp="[1, 2,")
    path = write_policy(tmp_path / "bad.onnx", meta, contract.obs_dim, contract.num_actions)
    with pytest.raises(ContractError, match="'kp' is not valid JSON"):
        PolicyContract.from_onnx(path)


def test_bare_strings_accepted_for_string_keys(contract, tmp_path):
    meta = dict(contract.to_metadata(), embodiment="g1_inspire", policy_kind="teacher")
    meta["robot_hoi.version"] = "0.1.0"
    path = write_policy(tmp_path / "p.onnx", meta, contract.obs_dim, contract.num_actions)
    c = PolicyContract.from_onnx(path)
    assert c.embodiment == "g1_inspire" and c.policy_kind == "teacher"


def test_obs_dim_mismatch_with_graph(contract, tmp_path):
    path = write_policy(tmp_path / "p.onnx", contract.to_metadata(), contract.obs_dim + 3, contract.num_actions)
    with pytest.raises(ContractError, match=f"sum to {contract.obs_dim} but input 'obs' has {contract.obs_dim + 3}"):
        PolicyContract.from_onnx(path)


def test_action_dim_mismatch_with_graph(contract, tmp_path):
    path = write_policy(tmp_path / "p.onnx", contract.to_metadata(), contract.obs_dim, 29)
    with pytest.raises(ContractError, match="41 entries but output 'actions' has 29"):
        PolicyContract.from_onnx(path)


@pytest.mark.parametrize("names,expected", [
    ({"input_name": "observation"}, "one input named 'obs'"),
    ({"output_name": "mu"}, "no output named 'actions'"),
])
def test_wrong_io_names(contract, tmp_path, names, expected):
    path = write_policy(tmp_path / "p.onnx", contract.to_metadata(), contract.obs_dim, contract.num_actions, **names)
    with pytest.raises(ContractError, match=expected):
        PolicyContract.from_onnx(path)


def test_gains_within_tolerance_pass(contract, tmp_path):
    path = _edited_yaml(tmp_path, lambda r: r["actuators"][4].update(kp=300 * (1 + 1e-4)))
    check_against_embodiment(contract, path)


def test_extra_outputs_are_refused(contract, tmp_path):
    from onnx import TensorProto, helper, numpy_helper

    n, a = contract.obs_dim, contract.num_actions
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["obs", "W"], ["actions"]), helper.make_node("Identity", ["actions"], ["value"])],
        "two_heads",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["b", n])],
        [helper.make_tensor_value_info("actions", TensorProto.FLOAT, ["b", a]),
         helper.make_tensor_value_info("value", TensorProto.FLOAT, ["b", a])],
        initializer=[numpy_helper.from_array(np.zeros((n, a), np.float32), "W")],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    helper.set_model_props(model, contract.to_metadata())
    path = tmp_path / "two_heads.onnx"
    path.write_bytes(model.SerializeToString())
    with pytest.raises(ContractError, match=r"exactly one output 'actions', got \['actions', 'value'\]"):
        PolicyContract.from_onnx(path)


def test_wrong_input_rank(contract, tmp_path):
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        [helper.make_node("Flatten", ["obs"], ["actions"], axis=1)],
        "g",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["b", 1, contract.obs_dim])],
        [helper.make_tensor_value_info("actions", TensorProto.FLOAT, ["b", contract.obs_dim])],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    helper.set_model_props(model, contract.to_metadata())
    path = tmp_path / "rank3.onnx"
    path.write_bytes(model.SerializeToString())
    ort.InferenceSession(str(path))  # a valid model, just not our contract
    with pytest.raises(ContractError, match="rank 2"):
        PolicyContract.from_onnx(path)


def test_not_an_onnx_file(tmp_path):
    path = tmp_path / "junk.onnx"
    path.write_bytes(b"not a model")
    with pytest.raises(ContractError, match="not a loadable ONNX model"):
        PolicyContract.from_onnx(path)
    with pytest.raises(DeployError, match="not found"):
        PolicyContract.from_onnx(tmp_path / "missing.onnx")


def _edited_yaml(tmp_path, edit) -> str:
    raw = yaml.safe_load(EMBODIMENT_YAML.read_text())
    edit(raw)
    path = tmp_path / "g1_inspire.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


@pytest.mark.parametrize("edit,expected", [
    (lambda r: r["actuators"].insert(0, r["actuators"].pop(3)), "actuator 0 is 'left_hip_pitch_joint' but the config has"),
    (lambda r: r["actuators"].append({"name": "extra_joint", "kp": 1, "kd": 0, "default": 0, "action_scale": 1}),
     "41 actuators vs 42"),
    (lambda r: r.update(control_dt=0.02), "control_dt"),
    (lambda r: r.update(name="h1_inspire"), "embodiment is 'g1_inspire'"),
    (lambda r: r["hands"]["right"]["channels"][5].update(open_rad=-0.2), "hand right 'thumb_rotate' maps open/closed"),
    (lambda r: r["actuators"][4].update(kp=40), "left_ankle_pitch_joint kp 300 vs 40 in the config"),
    (lambda r: r["actuators"][3].update(kd=2.5), "left_knee_joint kd 4 vs 2.5 in the config"),
    (lambda r: r["actuators"][18].update(default=0.8), "left_elbow_joint default pose 1.0000 vs 0.8000 rad"),
])
def test_embodiment_mismatch_is_refused(contract, tmp_path, edit, expected):
    path = _edited_yaml(tmp_path, edit)
    with pytest.raises(ContractError) as info:
        check_against_embodiment(contract, path)
    assert expected in str(info.value) and str(path) in str(info.value)


def test_embodiment_match_with_copied_yaml(contract, tmp_path):
    shutil.copy(EMBODIMENT_YAML, tmp_path / "copy.yaml")
    check_against_embodiment(contract, tmp_path / "copy.yaml")


def test_which_inputs_a_policy_needs():
    emb = load_embodiment(EMBODIMENT_YAML)
    proprio = make_contract(emb, obs_terms=["projected_gravity", "joint_pos", "last_action"])
    assert not proprio.uses_reference and not proprio.uses_object
    ref_only = make_contract(emb, obs_terms=["joint_pos", "ref_object_pos"])
    assert ref_only.uses_reference and not ref_only.uses_object  # the reference object comes from the motion
    assert make_contract(emb, obs_terms=["object_rot"]).uses_object
    # the pose tracker: the object terms read the object and the pelvis, the pelvis-relative reference the pelvis;
    # proprioception, ref_joint_pos and ref_root_local (the reference seen from itself) read neither
    tracker_free = make_contract(emb, obs_terms=["projected_gravity", "joint_pos", "ref_joint_pos", "ref_root_local"])
    assert tracker_free.uses_reference and tracker_free.tracked_poses == () and not tracker_free.needs_tracker
    assert ref_only.tracked_poses == ("robot",) and make_contract(emb, obs_terms=["ref_root_rot"]).needs_tracker
    assert make_contract(emb, obs_terms=["joint_pos", "object_pos"]).tracked_poses == ("robot", "object")
    assert json.loads(tracker_free.to_metadata()["tracker"]) == []


def test_a_tracker_record_that_contradicts_the_observation_is_refused(contract, tmp_path):
    assert json.loads(contract.to_metadata()["tracker"]) == ["robot", "object"]
    meta = dict(contract.to_metadata(), tracker=json.dumps([]))  # claims no mocap while reading object_pos
    path = write_policy(tmp_path / "bad.onnx", meta, contract.obs_dim, contract.num_actions)
    with pytest.raises(ContractError, match=r"metadata 'tracker' says the policy reads \[\] from the pose tracker, "
                                            r"its obs_spec reads \['robot', 'object'\]"):
        PolicyContract.from_onnx(path)
    del meta["tracker"]  # files written before the key: derived from obs_spec
    assert PolicyContract.from_onnx(write_policy(tmp_path / "old.onnx", meta, contract.obs_dim,
                                                 contract.num_actions)).needs_tracker


@pytest.mark.parametrize("task", [[1], {"env": 3}, {"world": {}}])
def test_malformed_task_record_is_refused(contract, tmp_path, task):
    meta = dict(contract.to_metadata(), task=json.dumps(task))
    path = write_policy(tmp_path / "bad.onnx", meta, contract.obs_dim, contract.num_actions)
    with pytest.raises(ContractError, match=r"metadata 'task' must be null or \{'env'"):
        PolicyContract.from_onnx(path)


def test_task_record_round_trips(contract, tmp_path):
    task = {"env": {"object_friction": 0.5, "terminations": {"max_contact_loss_frames": 10}}}
    meta = dict(contract.to_metadata(), task=json.dumps(task))
    back = PolicyContract.from_onnx(write_policy(tmp_path / "p.onnx", meta, contract.obs_dim, contract.num_actions))
    assert back.task == task and back.to_metadata() == meta


def test_skills_are_the_clips_with_a_motion(contract, tmp_path):
    sha = "ab" * 32
    data = {"clips": [{"name": "walk", "source": "embedded:walk:0", "motion": {"file": "p.motion.npz", "sha256": sha}},
                      {"name": "lift", "source": "embedded:lift_place",
                       "motion": {"file": "p.lift.motion.npz", "sha256": sha}},
                      {"name": "no_sidecar", "source": "x.pt"}], "license": ""}
    meta = dict(contract.to_metadata(), data=json.dumps(data))
    back = PolicyContract.from_onnx(write_policy(tmp_path / "p.onnx", meta, contract.obs_dim, contract.num_actions))
    assert list(back.skills) == ["walk", "lift"]
    path, info = back.skill_reference("lift")
    assert path == tmp_path / "p.lift.motion.npz" and info.sha256 == sha
    with pytest.raises(ContractError, match="no skill 'squat'; its skills: walk, lift"):
        back.skill_reference("squat")
    assert PolicyContract.from_onnx(write_policy(tmp_path / "q.onnx", contract.to_metadata(), contract.obs_dim,
                                                 contract.num_actions)).skills == {}


@pytest.mark.parametrize("motion,expected", [({"file": "../p.motion.npz", "sha256": "ab" * 32}, "bare file name"),
                                             ({"file": "p.motion.npz", "sha256": "ab"}, "sha256")])
def test_a_malformed_skill_motion_is_refused(contract, tmp_path, motion, expected):
    data = {"clips": [{"name": "walk", "motion": motion}], "license": ""}
    meta = dict(contract.to_metadata(), data=json.dumps(data))
    path = write_policy(tmp_path / "bad.onnx", meta, contract.obs_dim, contract.num_actions)
    with pytest.raises(ContractError, match=rf"metadata 'data' clip 0 motion .*{expected}"):
        PolicyContract.from_onnx(path)
