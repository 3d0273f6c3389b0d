"""Registration of spreadgym's environments with gymnasium (called on `import spreadgym`).

Entry points are strings, so registering imports no environment module.

**v1** (the benchmark, docs/benchmark.md): one namespaced id per task, `spreadgym/NAME-v1`,
each a YAML of configs/envs/ (`TASKS`). The ladder of design tasks, from the first rung:
SpinnerDesign, SpinnerDesignPitch, SpinnerDesignTwin, SpinnerDesignWind,
SpinnerDesignPlates, and the hidden-parameter SpinnerDesignRobust; the tuning tasks
SpreaderTuning and SpreaderTuningHard. Gymnasium's passive env checker is on, applied by
the entry points with its failed-first-reset case fixed, and SpreaderTuning's TimeLimit is
checked against its `max_steps` (envs/conventions.py).

**v0** (deprecated, kept working as before): `spreadgym/NAME-v0`, `NAME-v0` and
`spreadgym:NAME-v0` (the last so that tools which check an id against the registry before
making it accept the form that works in any process), checker off as it was. Making one
warns (DeprecationWarning) and names the v1 id.

Gymnasium (1.x) has no plugin mechanism: an id is found only in a process that has
imported `spreadgym`. In a fresh process (SubprocVecEnv, async vector envs, RLlib env
runners) the `module:id` form imports it first: `gym.make("spreadgym:spreadgym/NAME-v1")`
(as `ale_py:ALE/Pong-v5`), docs/rl-tools.md.
"""

from __future__ import annotations

import gymnasium

from spreadgym.config.resources import config_dir, read_yaml

DESIGN_ENTRY = "spreadgym.envs.conventions:spinner_design"
DESIGN_VECTOR = "spreadgym.envs.vector:SpinnerDesignVectorEnv"
TUNING_ENTRY = "spreadgym.envs.conventions:spreader_tuning"

TASKS = {
    # name: (entry point, config under configs/envs/)
    "SpinnerDesign-v1": (DESIGN_ENTRY, "spinner_design_v1"),
    "SpinnerDesignPitch-v1": (DESIGN_ENTRY, "spinner_design_pitch_v1"),
    "SpinnerDesignTwin-v1": (DESIGN_ENTRY, "spinner_design_twin_v1"),
    "SpinnerDesignWind-v1": (DESIGN_ENTRY, "spinner_design_wind_v1"),
    "SpinnerDesignPlates-v1": (DESIGN_ENTRY, "spinner_design_plates_v1"),
    "SpinnerDesignRobust-v1": (DESIGN_ENTRY, "spinner_design_robust_v1"),
    "SpreaderTuning-v1": (TUNING_ENTRY, "spreader_tuning_v1"),
    "SpreaderTuningHard-v1": (TUNING_ENTRY, "spreader_tuning_hard_v1"),
}
"""The v1 tasks. No `reward_threshold`: the reachable reward differs from job to job, so no
single number means solved; the benchmark normalises per job instead (docs/benchmark.md)."""

LADDER = ("SpinnerDesign-v1", "SpinnerDesignPitch-v1", "SpinnerDesignTwin-v1", "SpinnerDesignWind-v1",
          "SpinnerDesignPlates-v1", "SpinnerDesignRobust-v1")
"""The design rungs, easiest first."""

ENVS = {
    "SpinnerDesign-v0": {"entry_point": "spreadgym.envs.registration:spinner_design_v0",
                         "vector_entry_point": DESIGN_VECTOR},
    "SpreaderTuning-v0": {"entry_point": "spreadgym.envs.registration:spreader_tuning_v0"},
}
"""The deprecated v0 tasks, under every form they had."""
ID_FORMS = ("spreadgym/{}", "{}", "spreadgym:{}")
NAMESPACE = "spreadgym"


def env_config_name(env_id: str) -> str:
    """configs/envs/ name of a registered spreadgym id (any form)."""
    spec = gymnasium.spec(env_id.split(":", 1)[1] if env_id.startswith("spreadgym:") else env_id)
    return spec.kwargs.get("config", "spreader_tuning" if "Tuning" in spec.name else "spinner_design")


def max_steps_of(config: str) -> int:
    """`max_steps` of a shipped SpreaderTuning YAML, following `extends` (plain YAML: no env import)."""
    raw = read_yaml(config_dir() / "envs" / f"{config}.yaml")
    while "max_steps" not in raw and "extends" in raw:
        raw = read_yaml(config_dir() / "envs" / f"{raw['extends']}.yaml")
    return int(raw["max_steps"])


def spinner_design_v0(**kwargs):
    """`SpinnerDesign-v0` as it was, with a deprecation note."""
    from spreadgym.envs.spinner_design import SpinnerDesignEnv

    _deprecated("SpinnerDesign")
    return SpinnerDesignEnv(**kwargs)


def spreader_tuning_v0(**kwargs):
    """`SpreaderTuning-v0` as it was, with a deprecation note."""
    from spreadgym.envs.spreader_tuning import SpreaderTuningEnv

    _deprecated("SpreaderTuning")
    return SpreaderTuningEnv(**kwargs)


def _deprecated(name: str) -> None:
    gymnasium.logger.deprecation(
        f"{name}-v0 is deprecated: its evaluation jobs are among its training contexts and its ids are three; "
        f"use spreadgym/{name}-v1 (docs/environments.md, version history)")


def register_envs() -> None:
    time_limit = gymnasium.envs.registration.WrapperSpec(
        "TimeLimitAgrees", "spreadgym.envs.conventions:TimeLimitAgrees", {})
    for name, (entry, config) in TASKS.items():
        env_id = f"{NAMESPACE}/{name}"
        if env_id in gymnasium.registry:
            continue
        if entry == DESIGN_ENTRY:
            extra = {"vector_entry_point": DESIGN_VECTOR}
        else:
            extra = {"max_episode_steps": max_steps_of(config), "additional_wrappers": (time_limit,)}
        # the entry points apply the passive checker themselves (fixed), so gymnasium's is off
        gymnasium.register(id=env_id, entry_point=entry, kwargs={"config": config}, disable_env_checker=True,
                           **extra)
    limits = {"SpreaderTuning-v0": max_steps_of("spreader_tuning")}
    for name, entry in ENVS.items():
        for form in ID_FORMS:
            env_id = form.format(name)
            if env_id not in gymnasium.registry:
                gymnasium.register(id=env_id, max_episode_steps=limits.get(name), disable_env_checker=True, **entry)
