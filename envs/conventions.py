"""What `gym.make` gives around every v1 env (envs/registration.py).

1. **Gymnasium's passive env checker, on, with the failed-first-reset case fixed.**
   Gymnasium 1.4's `PassiveEnvChecker` marks the first reset as checked before calling it;
   when that reset raises (a bad `options["context"]`), nothing is stored, and the first
   step after the next good reset fails inside the checker (`TypeError: cannot unpack
   non-iterable NoneType object`). `PassiveEnvChecker` here is gymnasium's, re-armed after
   a first reset that raised. The entry points (`spinner_design`, `spreader_tuning`) apply
   it themselves, where gymnasium would put its own (the lowest wrapper), so the registry
   turns gymnasium's off (`disable_env_checker=True`) and `env.spec.disable_env_checker`
   reads False as for any checked env. docs/rl-tools.md has the upstream report.
2. **The TimeLimit agrees with `max_steps`** (SpreaderTuning, `TimeLimitAgrees`, the
   registry's `additional_wrappers`): the env truncates itself at `max_steps` (its
   observation counts the steps left); gymnasium's TimeLimit comes from the registry
   (`max_episode_steps`, the YAML's `max_steps`) or `gym.make(..., max_episode_steps=N)`.
   When they differ, `gym.make` fails with a one-line ConfigError saying what to pass.
   (Gymnasium refuses `additional_wrappers` on an id with a `vector_entry_point`; the
   design tasks have no `max_steps`.)
"""

from __future__ import annotations

import gymnasium as gym

from spreadgym.errors import ConfigError


class PassiveEnvChecker(gym.wrappers.PassiveEnvChecker):
    """Gymnasium's passive env checker, whose first-reset check runs again after a first reset that raised."""

    def reset(self, *, seed=None, options=None):
        first = not self.checked_reset
        try:
            return super().reset(seed=seed, options=options)
        except BaseException:
            if first:  # nothing was stored for the data-reuse check of the first step: check the next reset
                self.checked_reset = False
            raise


def spinner_design(**kwargs) -> gym.Env:
    """Entry point of the SpinnerDesign v1 tasks: the env under the passive checker."""
    from spreadgym.envs.spinner_design import SpinnerDesignEnv

    return PassiveEnvChecker(SpinnerDesignEnv(**kwargs))


def spreader_tuning(**kwargs) -> gym.Env:
    """Entry point of the SpreaderTuning v1 tasks: the env under the passive checker."""
    from spreadgym.envs.spreader_tuning import SpreaderTuningEnv

    return PassiveEnvChecker(SpreaderTuningEnv(**kwargs))


class TimeLimitAgrees(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Refuses a TimeLimit that disagrees with the env's `max_steps` (one-line ConfigError)."""

    def __init__(self, env: gym.Env):
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        max_steps = env.unwrapped.config.max_steps
        limit = env.spec.max_episode_steps if env.spec is not None else None
        if limit is not None and limit != max_steps:
            raise ConfigError("max_episode_steps", f"the TimeLimit ({limit}) and the env's max_steps ({max_steps}) "
                                                   f"disagree; pass both: gym.make(id, max_steps={max_steps}, "
                                                   f"max_episode_steps={max_steps})")
