"""Gymnasium layer of spreadgym (installed as spreadgym.envs).

Public helpers for tools outside gymnasium's own API (docs/rl-tools.md):

* `setting_ranges(env)`, `settings_to_action(env, settings)`, `action_to_settings(env, action)`:
  physical settings (rpm, degrees) <-> the unit vector in [-1, 1] of the action
  (SpinnerDesign) or of the observation's `setting:*` entries (SpreaderTuning);
* `register_rllib()`: makes the `spreadgym/...` ids resolvable in RLlib's env runners.

This module imports only on call, so `import spreadgym` stays light.
"""

from __future__ import annotations

import functools
from typing import Any, Mapping

import numpy as np


def _settings_map(env):
    """The SettingsMap of a (wrapped or vector) spreadgym env."""
    task = getattr(env.unwrapped, "task", None)
    if task is None:
        raise TypeError(f"{env!r} is not a spreadgym env (it has no task)")
    return task.settings_map


def setting_ranges(env) -> dict[str, tuple[float, float]]:
    """Each setting's name and range in action order: rpm, pitch_deg (or pitch_deg[k]),
    deflectors[i].angle_deg, feed.radius_m, feed.angle_deg (the last three where adjustable)."""
    smap = _settings_map(env)
    return {name: (float(lo), float(hi)) for name, lo, hi in zip(smap.names, smap.low, smap.high)}


def settings_to_action(env, settings: Mapping[str, Any]) -> np.ndarray:
    """The unit vector (float32) of physical settings given as in `info["settings"]`.

    `settings` holds `rpm`, `pitch_deg` (a number, or one per vane when the env has
    `pitch_per_vane`), `deflector_angle_deg` (one per adjustable deflector; may be
    left out when there is none) and `feed_radius_m` / `feed_angle_deg` where the scene
    makes the drop point adjustable. A value outside its range is a ConfigError naming it.
    """
    from spreadgym.envs.common.actions import Settings
    from spreadgym.errors import ConfigError

    smap = _settings_map(env)
    feed = [key.replace(".", "_") for key in smap.feed_keys]
    known = ["rpm", "pitch_deg", "deflector_angle_deg", *feed]
    unknown = set(settings) - set(known)
    if unknown:
        raise ConfigError(f"settings.{sorted(unknown)[0]}", f"unknown key; known: {', '.join(known)}")
    missing = [key for key in ("rpm", "pitch_deg", *feed) if key not in settings]
    if missing:
        needed = ", ".join(["rpm", "pitch_deg", *feed])
        raise ConfigError(f"settings.{missing[0]}", f"required; this env needs {needed}")
    pitch = np.atleast_1d(np.asarray(settings["pitch_deg"], dtype=np.float64))
    angles = np.atleast_1d(np.asarray(settings.get("deflector_angle_deg", []), dtype=np.float64))
    values = np.concatenate([[float(settings["rpm"])], pitch, angles, [float(settings[key]) for key in feed]])
    if values.size != smap.size:
        raise ConfigError("settings", f"expected {smap.size} values ({', '.join(smap.names)}), got {values.size}")
    for name, value, lo, hi in zip(smap.names, values, smap.low, smap.high):
        if not lo <= value <= hi:
            raise ConfigError(f"settings.{name}", f"{value:g} is outside its range [{lo:g}, {hi:g}]")
    given = Settings.from_dict({**settings, "pitch_deg": pitch, "deflector_angle_deg": angles})
    return smap.to_unit(given).astype(np.float32)


def action_to_settings(env, action) -> dict:
    """Physical settings of a unit vector (clipped to [-1, 1]; checked as `step` checks
    an action), laid out as `info["settings"]`."""
    from spreadgym.envs.common.actions import check_action

    smap = _settings_map(env)
    return smap.to_settings(check_action(action, smap.size)).as_dict()


def register_rllib() -> None:
    """Register every spreadgym id (v1: `spreadgym/NAME-v1` and `spreadgym:spreadgym/NAME-v1`; v0:
    both its forms) with Ray Tune's env registry.

    RLlib's env runners are fresh processes; env ids registered this way reach them
    as creators that import spreadgym first. `env_config` becomes `gym.make` kwargs.
    Needs `ray[rllib]` (the `rllib` extra).
    """
    from ray.tune.registry import register_env

    from spreadgym.envs.registration import ENVS, TASKS

    ids = [f"spreadgym/{name}" for name in TASKS] + [f"spreadgym:spreadgym/{name}" for name in TASKS]
    ids += [f"spreadgym/{name}" for name in ENVS] + [f"spreadgym:{name}" for name in ENVS]  # v0, deprecated
    for env_id in ids:
        register_env(env_id, functools.partial(_rllib_env, env_id))


def _rllib_env(env_id: str, env_config: Mapping[str, Any]):
    import gymnasium

    import spreadgym  # noqa: F401  (registers the envs in this worker)

    return gymnasium.make(env_id, **dict(env_config))
