"""The training env's deployable observation equals the deploy runtime's builder for the same state."""

import json

import numpy as np
import pytest
import torch

from robot_hoi.data.objects import box_asset
from robot_hoi.embodiment import build_model, load_embodiment
from robot_hoi.export.metadata import policy_metadata
from robot_hoi.export.motion_sidecar import deploy_motion
from robot_hoi.tasks.interaction.env import InteractionEnv
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
from robot_hoi.tasks.interaction.mdp.observations import STUDENT_TERMS, student_observation_spec
from robot_hoi.tasks.interaction.scene_setup import InteractionScene

from .test_interaction_env import standing_reference

deploy_contract = pytest.importorskip("deploy.contract")
deploy_obs = pytest.importorskip("deploy.observations")


def test_student_observation_matches_deploy_builder():
    emb = load_embodiment("g1_inspire")
    scene = InteractionScene(emb, box_asset((0.4, 0.4, 0.3)))
    reference = standing_reference(scene)
    # make the reference move so every ref_* term and keyframe offset matters
    t = torch.arange(reference.num_frames, dtype=torch.float32)[:, None]
    reference.link_pos = reference.link_pos + 0.01 * t[:, :, None] * torch.tensor([1.0, 0.5, 0.0])
    reference.robot_qpos = reference.robot_qpos.clone()
    reference.robot_qpos[:, 0] += 0.01 * t[:, 0]
    # and turn (ref_root_local: the reference's pelvis path in its own heading frame)
    from robot_hoi.utils.torch_rot import quat_from_yaw, quat_mul

    reference.robot_qpos[:, 3:7] = quat_mul(quat_from_yaw(0.03 * t[:, 0]), reference.robot_qpos[:, 3:7])
    reference.object_pos = reference.object_pos + 0.02 * t * torch.tensor([1.0, 0.0, 0.1])
    cfg = InteractionEnvCfg(num_envs=4, nthread=2, seed=5, student_obs_terms=tuple(STUDENT_TERMS))
    cfg.init.stand_start_probability = 0.0
    cfg.psi.enabled = False
    env = InteractionEnv(cfg, scene, [reference])
    env.reset()
    for _ in range(3):
        obs, *_ = env.step(0.3 * torch.randn(4, env.num_actions, generator=torch.Generator().manual_seed(1)))

    metadata = policy_metadata(emb, build_model(emb), policy_kind="student", obs_spec=student_observation_spec(env),
                               keyframes=cfg.student_keyframes, action_clip=cfg.action_clip, clips=[])
    contract = deploy_contract.PolicyContract.from_metadata({k: json.dumps(v) for k, v in metadata.items()})
    builder = deploy_obs.ObservationBuilder(contract, deploy_motion(reference))

    hand_ids = [i for i in range(env.num_actions) if i not in env.body_actuator_ids]
    for i in range(env.num_envs):
        hand_rad = env.joint_pos[i, hand_ids].double().numpy()
        units = np.concatenate([emb.rad_to_units("left", hand_rad[:6]), emb.rad_to_units("right", hand_rad[6:])])
        in_range = (units > 0) & (units < 1000)  # the Inspire reports angles inside its stroke only
        forces_n = env.contact_force[i, env.hand_force_sensor_ids].norm(dim=-1).double().numpy()
        state = deploy_obs.RobotState(
            joint_pos=env.joint_pos[i, env.body_actuator_ids].double().numpy(),
            joint_vel=env.joint_vel[i, env.body_actuator_ids].double().numpy(),
            imu_quat_wxyz=env.root_quat[i].double().numpy(), gyro=env.root_ang_vel[i].double().numpy(),
            hand_angles=units, hand_forces=forces_n / 9.81e-3,
            pelvis_pos=env.root_pos[i].double().numpy(), pelvis_quat_wxyz=env.root_quat[i].double().numpy(),
            object_pos=env.object_pos[i].double().numpy(), object_quat_wxyz=env.object_quat[i].double().numpy(),
            last_action=env.last_actions[i].double().numpy(), tick=int(env.ref_index[i] - env.clip_start[0]),
        )
        expected = builder.terms(state)
        start = 0
        for term in contract.obs_spec:
            got = obs["student"][i, start:start + term.size].double().numpy()
            want = expected[term.name]
            if term.name == "joint_pos":  # hand channels clipped to the stroke on hardware
                mask = np.concatenate([np.ones(len(env.body_actuator_ids), bool), in_range])
                got, want = got[mask], want[mask]
            np.testing.assert_allclose(got, want, atol=2e-4, err_msg=term.name)
            start += term.size
        assert start == obs["student"].shape[1]
