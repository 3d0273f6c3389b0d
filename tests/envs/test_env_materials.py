"""A user's fertilizer in the envs (the `materials` keyword): a value-for-value copy of a
library fertilizer, under its own name, steps exactly as the original does."""

from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence

from spreadgym.errors import ConfigError

DESIGN_ID = "spreadgym/SpinnerDesign-v0"
SMALL = {"granules": 48, "model": "compiled"}


def _episode(fertilizer: str, **kwargs):
    env = gym.make(DESIGN_ID, context={"fertilizers": [fertilizer]}, **SMALL, **kwargs)
    obs, _ = env.reset(seed=7)
    step = env.step(np.full(env.action_space.shape, 0.25, dtype=np.float32))
    env.close()
    return obs, step[1], step[4]["metrics"]


def test_a_copy_of_a_library_fertilizer_steps_as_the_original(copied_fertilizer):
    path, name = copied_fertilizer
    obs, reward, metrics = _episode(name, materials=str(path))
    obs0, reward0, metrics0 = _episode("compound-10-16-10")
    assert data_equivalence(obs, obs0, exact=True)
    assert reward == reward0 and metrics == metrics0


def test_a_user_fertilizer_without_its_file_and_a_bad_file_are_one_line(copied_fertilizer, tmp_path):
    _path, name = copied_fertilizer
    with pytest.raises(ConfigError, match=f"context.fertilizers: unknown fertilizer '{name}'"):
        gym.make(DESIGN_ID, context={"fertilizers": [name]}, **SMALL)
    with pytest.raises(ConfigError, match="materials: .*nothing.yaml: file not found") as info:
        gym.make(DESIGN_ID, materials=str(tmp_path / "nothing.yaml"), **SMALL)
    assert "\n" not in str(info.value)


def test_auto_reads_the_rolling_resistance_from_the_library_the_run_is_given(copied_fertilizer):
    """A user fertilizer rolling harder than the compiled model was checked at (0.6) sends `auto` to the full
    model through the library the run is given (an env's `materials`), not the process's."""
    from spreadgym.config.materials import load_library
    from spreadgym.config.scene import load_scene
    from spreadgym.physics.selection import VALIDATED, choose_model

    path, name = copied_fertilizer
    rough_library = load_library(extra=path)  # the copy, then its rolling resistance raised over it
    rough_library = replace(rough_library, fertilizers={**rough_library.fertilizers, name: replace(
        rough_library.fertilizer(name), rolling_resistance={"mc": 0.8, "steel": 0.8, "pvc": 0.8})})
    scene = load_scene("paper", {"fertilizer": name})
    assert 0.8 > VALIDATED["rolling_resistance"][1]
    assert choose_model(scene, "auto", load_library(extra=path))[0] == "compiled"
    model, reason = choose_model(scene, "auto", rough_library)
    assert model == "pymunk" and "rolling" in reason
