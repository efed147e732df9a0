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
