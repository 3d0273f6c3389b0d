"""The env benchmarks run end to end at their smallest (a tuning episode that ends during
the warm-up once made the env section raise ResetNeeded) and report sane rates."""

import math

from spreadgym.agents.commands.bench import env_steps_per_second, vector_env_steps_per_second


def test_env_section_runs_every_env_and_scene():
    rows = env_steps_per_second(steps=2, repeats=1)
    scenes = ("paper", "field", "twin-field", "paper-deflectors")
    assert [(r["env"].split(":")[1], r["scene"]) for r in rows] == [
        (env, scene) for env in ("SpinnerDesign-v0", "SpreaderTuning-v0") for scene in scenes]
    assert all(r["model"] == "compiled" and r["steps_per_s"] > 0 and math.isfinite(r["ms_per_step"]) for r in rows)


def test_vector_env_section_compares_with_the_single_env():
    rows = vector_env_steps_per_second(batch=2, vector_steps=1, repeats=1)
    assert [r["batch"] for r in rows] == [2, 1]
    assert rows[1]["ratio_to_single"] == 1.0
    assert rows[0]["ratio_to_single"] == rows[0]["steps_per_s"] / rows[1]["steps_per_s"]


def test_training_env_rows_time_both_kinds_and_check_their_rewards(monkeypatch):
    """`train`'s envs as SubprocVecEnv and as the batched vector env; the check that both
    gave the same rewards fails when they step different envs (here: seeded apart)."""
    import pytest

    from spreadgym.agents import training_env
    from spreadgym.agents.commands.bench import training_env_rows

    rows = training_env_rows(designs=2, repeats=1, counts=(2,))
    assert [r["what"] for r in rows] == ["train env, SubprocVecEnv, 2 envs", "train env, batched vector env, 2 envs"]
    assert all(r["designs_per_s"] > 0 for r in rows)
    made = training_env.make_training_env
    monkeypatch.setattr(training_env, "make_training_env",
                        lambda cfg, errors: made(cfg.replace(seed=cfg.seed + (cfg.vec_env == "batched")), errors))
    with pytest.raises(AssertionError, match="rewards differ"):
        training_env_rows(designs=2, repeats=1, counts=(2,))
