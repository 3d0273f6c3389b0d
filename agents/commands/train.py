"""`spreadgym train`: train a PPO or SAC policy (stable-baselines3, torch CPU) on a spreadgym env."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from spreadgym.agents.training import train
from spreadgym.cli import arguments
from spreadgym.config.overrides import parse_assignments
from spreadgym.out_folder import OutFolder, named_files


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--algo", required=True, choices=("ppo", "sac"), help="algorithm")
    parser.add_argument("--env", help="env id (default: the config's, spreadgym:SpinnerDesign-v0)")
    parser.add_argument("--config", type=Path, metavar="YAML",
                        help="hyperparameter YAML (default: configs/agents/ALGO.yaml)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a config key, VALUE parsed as YAML (e.g. n_envs=1, env_kwargs.granules=100)")
    parser.add_argument("--timesteps", type=arguments.COUNT, metavar="N",
                        help="total env steps (default: the config's)")
    parser.add_argument("--seed", type=arguments.SEED, metavar="S", help="seed (default: the config's)")
    parser.add_argument("--max-minutes", type=arguments.real(0.0, 1e6, low_open=True), metavar="M",
                        help="stop (and save) after M minutes of training in this invocation")
    parser.add_argument("--out", type=arguments.output_folder, required=True, metavar="DIR",
                        help="run folder: model.zip, config.yaml, checkpoints/, tb/ (a run there is resumed)")
    arguments.force_flag(parser)


def run(args: argparse.Namespace) -> int:
    def log(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    out = OutFolder(args.out, "train", ("model.zip", "config.yaml", "vecnormalize.pkl"), named_files(args.config),
                    args.force, keeps_partial=True, marker="config.yaml")
    out.check()
    with out.writing() as folder:  # checkpoints are kept when interrupted: the next run resumes them
        result = train(args.algo, folder, config_path=args.config, overrides=parse_assignments(args.overrides),
                       env_id=args.env, timesteps=args.timesteps, seed=args.seed, max_minutes=args.max_minutes,
                       log=log)
    resumed = f", resumed from {result.resumed_from} steps" if result.resumed_from is not None else ""
    print(f"trained {args.algo} to {result.num_timesteps} steps ({result.stopped}{resumed}) "
          f"in {result.wall_s / 60:.1f} min")
    print(f"wrote {result.out_dir / 'model.zip'}")
    print(f"wrote {result.out_dir / 'config.yaml'}")
    if (result.out_dir / "vecnormalize.pkl").is_file():
        print(f"wrote {result.out_dir / 'vecnormalize.pkl'}")
    print(f"checkpoints in {result.out_dir / 'checkpoints'}, TensorBoard logs in {result.out_dir / 'tb'}")
    return 0
