"""Chart cells from a trained SpinnerDesign policy (`--method policy`, `policy+search`).

The policy (saved by `spreadgym train`, loaded with `agents.training.load_policy`) sees
the cell as a SpinnerDesign job: its env is reset with the cell's fertilizer and width
as the context (the rest of the context as the env's config draws it, from a seed of the
cell's seed sequence), and its deterministic action sets the settings. The action's
settings are put into the cell's scene and read back as a unit vector of the chart's
settings space, so a policy trained with other ranges still lands on the same dial.
No simulation runs to make the proposal.

A policy is shipped for a scene in `configs/policies/<scene name>/` (model.zip, the run's
config.yaml and a README saying how it was trained); it is the default of `--method
policy` and `policy+search` on that scene (`shipped_policy`).
"""

from __future__ import annotations

import hashlib
from functools import lru_cache
from pathlib import Path

import numpy as np

from spreadgym.config.resources import config_dir
from spreadgym.config.scene import Scene, scene_with
from spreadgym.errors import ConfigError, SpreadgymError

DESIGN_ENV = "SpinnerDesign-v0"
POLICIES = "policies"  # under the shipped configs: one folder per scene name


def shipped_policy(scene: Scene, method: str) -> Path:
    """The run folder of the policy shipped for `scene`'s name; a one-line SpreadgymError
    naming --policy where none is shipped."""
    root = config_dir() / POLICIES
    folder = root / scene.name
    if not (folder / "model.zip").is_file():
        shipped = sorted(p.name for p in root.iterdir() if (p / "model.zip").is_file()) if root.is_dir() else []
        raise SpreadgymError(f"--policy: needed by --method {method} on scene {scene.name!r}: no policy is shipped "
                             f"for it (shipped: {', '.join(shipped) or 'none'}); give one saved by spreadgym train")
    return folder


@lru_cache(maxsize=2)
def _loaded(path: str, digest: str):
    """(policy, env) of a policy file, once per process (`digest` keys a changed file apart)."""
    import gymnasium

    from spreadgym.agents.training import load_policy

    policy = load_policy(path, flag="--policy")
    if not policy.env_id.endswith(DESIGN_ENV):
        raise SpreadgymError(f"--policy {path}: trained on {policy.env_id}; a chart needs a {DESIGN_ENV} policy")
    return policy, gymnasium.make(policy.env_id, **policy.env_kwargs).unwrapped


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def check_policy(path, scene: Scene) -> tuple[str, str]:
    """(the policy file, its sha256): a SpinnerDesign policy trained on `scene`'s scene name."""
    file = Path(path)
    file = file / "model.zip" if file.is_dir() else file
    if not file.is_file():
        raise SpreadgymError(f"--policy {path}: no such file (expected DIR/model.zip written by spreadgym train)")
    digest = _digest(file)
    policy, env = _loaded(str(file), digest)
    trained_on = env.task.base_scene.name
    if trained_on != scene.name:
        raise SpreadgymError(f"--policy {path}: trained on scene {trained_on!r}; the chart's scene is {scene.name!r}")
    return str(file), digest


def policy_fertilizers(path: str, digest: str) -> tuple[str, ...]:
    """The fertilizers the policy's environment was trained on."""
    return tuple(_loaded(path, digest)[1].task.cfg.context.fertilizers)


def propose(spec, cell, seq: np.random.SeedSequence) -> np.ndarray:
    """The policy's settings for `cell`, as a unit vector of the chart's settings space."""
    policy, env = _loaded(spec.policy, spec.policy_sha256)
    context = {"fertilizer": cell.fertilizer, "target_swath_m": cell.width_m}
    try:
        obs, _ = env.reset(seed=int(seq.generate_state(1)[0]), options={"context": context})
    except ConfigError as exc:
        raise SpreadgymError(f"--policy {spec.policy}: cannot take {cell.fertilizer} at {cell.width_m:g} m "
                             f"({exc.key}: {exc.message})") from None
    action = np.asarray(policy.act(obs), dtype=float).reshape(-1)
    settings = env.task.settings_map.to_settings(np.clip(action, -1.0, 1.0))
    scene = spec.cell_scene(cell)
    proposed = scene_with(scene, env.task.settings_map.scene_overrides(settings))
    return spec.space(scene).scene_unit(proposed)
