"""The one console entry (`spreadgym`): command names mapped to the modules that run them.

Each command module defines `add_arguments(parser)` and `run(args) -> int`. The table
names modules by string, and only the module of the command being run is imported, so
the core's commands never import the envs or agents layers and `spreadgym materials`
does not load torch.
"""

COMMANDS: dict[str, tuple[str, str]] = {
    "materials": ("spreadgym.cli.materials",
                  "list fertilizers, surfaces and the measured fertilizer-surface pair properties"),
    "calibrate": ("spreadgym.cli.calibrate",
                  "spring-dashpot contact parameters from restitution, contact time and mass (Eqs. 8-10)"),
    "simulate": ("spreadgym.cli.simulate",
                 "simulate a scene: departure from the spinner, flight, tray pattern, CV and swath"),
    "reference": ("spreadgym.cli.reference",
                  "a converged pattern: independent runs of a scene pooled, CV and swath with standard errors"),
    "fit": ("spreadgym.cli.fit",
            "fit scene keys (friction, restitution, granule size, drag) to a measured tray test, "
            "with 90-percent intervals"),
    "study": ("spreadgym.cli.study",
              "rerun a published simulation study (paper: material, rpm, diameter; free vs locked rotation)"),
    "train": ("spreadgym.agents.commands.train",
              "train a PPO or SAC policy on a spreadgym env (resumes from DIR's checkpoints)"),
    "evaluate": ("spreadgym.agents.commands.evaluate",
                 "run a policy (deterministic) on the evaluation jobs: table, JSON and pattern plots"),
    "compare": ("spreadgym.agents.commands.compare",
                "compare policies with the baselines on the env's evaluation jobs (--seeds: normalised IQM, rliable)"),
    "demo": ("spreadgym.agents.commands.demo",
             "the main job: better spinner settings for a wider swath (CMA-ES on the fast model, "
             "before/after with the full model), table and pictures"),
    "advise": ("spreadgym.agents.commands.advise",
               "after a tray test: what to change on the machine for an even spread at the working width wanted"),
    "chart": ("spreadgym.agents.commands.chart", "spreading chart: settings per fertilizer and width, verified (Ray)"),
    "bench": ("spreadgym.agents.commands.bench",
              "run the benchmarks (speed, speed against accuracy) and write CSV/PNG under --out"),
    "serve": ("spreadgym.agents.commands.serve",
              "a local web app: move a setting and see the pattern; browse and run spreading charts"),
}
