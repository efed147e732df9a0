"""The object's torsional friction reaches the compiled scene of training and of sim2sim."""

import mujoco
import numpy as np
import pytest


@pytest.mark.parametrize("torsional", [0.0, 0.02])
def test_training_and_validation_scenes_get_the_objects_torsional_friction(torsional):
    from robot_hoi.data.synth import embedded_clip
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.sim.scene import OBJECT_BODY
    from robot_hoi.tasks.interaction.scene_setup import InteractionScene
    from sim2sim.scene import build_scene_bytes, load_model

    box = embedded_clip("lift_place").object
    training = InteractionScene(load_embodiment("g1_inspire"), box, torsional_friction=torsional).model
    validation = load_model(build_scene_bytes("g1_inspire", box, torsional_friction=torsional))
    for model in (training, validation):
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OBJECT_BODY)
        geom = int(np.flatnonzero(model.geom_bodyid == body)[0])
        assert model.geom_condim[geom] == (4 if torsional else 3)
        assert model.geom_friction[geom, 1] == pytest.approx(torsional or 0.005)


def _slide_under_push(friction: float, push_share: float) -> float:
    """Metres a flat 2 kg box (0.4 x 0.4 x 0.1 m, too flat to tip) slides in 0.5 s on the training scene's floor under
    a horizontal push of `push_share` x its weight at its centre, with the object's friction set to `friction`."""
    from robot_hoi.data.objects import box_asset
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.sim.scene import OBJECT_BODY
    from robot_hoi.tasks.interaction.scene_setup import InteractionScene

    box = box_asset((0.4, 0.4, 0.1), mass_kg=2.0)
    model = InteractionScene(load_embodiment("g1_inspire"), box, friction=friction).model
    data = mujoco.MjData(model)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OBJECT_BODY)
    adr = model.jnt_qposadr[model.body_jntadr[body]]
    data.qpos[adr:adr + 3] = [2.0, 0.0, 0.05]  # resting on the floor, 2 m from the robot
    for _ in range(int(0.2 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    start = data.xpos[body].copy()
    data.xfrc_applied[body, 0] = push_share * model.body_subtreemass[body] * 9.81
    for _ in range(int(0.5 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    return float(data.xpos[body, 0] - start[0])


def test_the_objects_own_friction_governs_its_floor_contact():
    # pushed with half its weight: slides at friction 0.3 (0.5 m in 0.5 s would be frictionless), holds at 0.9.
    # Before the fix both held: the floor's default 1.0 won, being the larger
    assert _slide_under_push(0.3, 0.5) > 0.1
    assert abs(_slide_under_push(0.9, 0.5)) < 0.005
