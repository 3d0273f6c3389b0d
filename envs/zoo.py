"""rl_zoo3 with spreadgym: where the shipped hyperparameter files are, and zoo's scripts with our ids.

    python -m spreadgym.envs.zoo path ppo              # path of the shipped ppo.yml (ppo, sac, tqc)
    python -m spreadgym.envs.zoo record_video --algo ppo --env spreadgym:SpinnerDesign-v0 -f logs

The second form imports `spreadgym` (which registers the envs) and then runs
`rl_zoo3.<script>` with the remaining arguments, for zoo scripts that have no
`--gym-packages` option (record_video, record_training). rl_zoo3 is optional
(`pip install "spreadgym[zoo]"`); docs/rl-tools.md has the commands.
"""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

from spreadgym.config.resources import config_dir

SCRIPTS = ("train", "enjoy", "record_video", "record_training")


def hyperparams_path(algo: str) -> Path:
    """The shipped zoo hyperparameter file of `algo` (ppo, sac or tqc)."""
    path = config_dir() / "agents" / "zoo" / f"{algo}.yml"
    if not path.is_file():
        names = ", ".join(sorted(p.stem for p in path.parent.glob("*.yml")))
        raise ValueError(f"no zoo hyperparameters for algo {algo!r}; shipped: {names}")
    return path


def main(argv: list[str]) -> int:
    if len(argv) == 2 and argv[0] == "path":
        try:
            print(hyperparams_path(argv[1]))
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        return 0
    if not argv or argv[0] not in SCRIPTS:
        print(f"usage: python -m spreadgym.envs.zoo path ALGO | {{{','.join(SCRIPTS)}}} [zoo arguments]",
              file=sys.stderr)
        return 2
    import spreadgym  # noqa: F401  (registers the envs in this process)

    sys.argv = [f"rl_zoo3.{argv[0]}", *argv[1:]]
    runpy.run_module(f"rl_zoo3.{argv[0]}", run_name="__main__", alter_sys=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
