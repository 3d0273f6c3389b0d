"""Registration of spreadgym's environments with gymnasium (called on `import spreadgym`).

Entry points are strings, so registering imports no environment module. Each env is
registered under three ids:

* `spreadgym/NAME-v0`, the namespaced id;
* `NAME-v0`, which `gym.make("spreadgym:NAME-v0")` looks up after importing
  `spreadgym` (gymnasium reads "module:id" as: import module, then look id up);
* `spreadgym:NAME-v0` itself, so that tools which check an id against the registry
  before making it (rl_zoo3's train) accept the form that works in any process.

Gymnasium (1.x) has no plugin mechanism: an id is found only in a process that has
imported `spreadgym`. Fresh worker processes (SubprocVecEnv, async vector envs, RLlib
env runners) import nothing of ours unless told, so there the `spreadgym:NAME-v0`
form is the one that always works (docs/rl-tools.md).

The passive env checker is off by default (`gym.make(..., disable_env_checker=False)`
turns it on): gymnasium 1.4's checker marks the first reset as checked even when it
raised (a bad `options["context"]`), and the next good reset and step then fail inside
the checker with a TypeError. The envs pass gymnasium's and SB3's full `check_env` in
the tests, and a failed reset leaves them needing a reset (ResetNeeded), not broken.

SpreaderTuning's time limit is the registry's `max_episode_steps`, the default
`max_steps` of its YAML: gymnasium's TimeLimit and the env's own truncation (whose
`steps_left` entry the observation needs) end the episode at the same step. Who
changes `max_steps` in `gym.make` passes the same `max_episode_steps`.
"""

from __future__ import annotations

import gymnasium

from spreadgym.config.resources import config_dir, read_yaml

ENVS = {
    "SpinnerDesign-v0": {
        "entry_point": "spreadgym.envs.spinner_design:SpinnerDesignEnv",
        "vector_entry_point": "spreadgym.envs.vector:SpinnerDesignVectorEnv",
    },
    "SpreaderTuning-v0": {"entry_point": "spreadgym.envs.spreader_tuning:SpreaderTuningEnv"},
}
ID_FORMS = ("spreadgym/{}", "{}", "spreadgym:{}")


def default_max_steps() -> int:
    """`max_steps` of the shipped SpreaderTuning YAML (read as plain YAML: no env import)."""
    return int(read_yaml(config_dir() / "envs" / "spreader_tuning.yaml")["max_steps"])


def register_envs() -> None:
    limits = {"SpreaderTuning-v0": default_max_steps()}
    for name, entry in ENVS.items():
        for form in ID_FORMS:
            env_id = form.format(name)
            if env_id not in gymnasium.registry:
                gymnasium.register(id=env_id, max_episode_steps=limits.get(name), disable_env_checker=True, **entry)
