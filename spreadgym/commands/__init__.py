"""CLI subcommands of the simulation core.

Each module here defines `NAME`, `HELP`, `add_arguments(parser)` and `run(args) -> int`.
The console script (spreadgym.agents.cli) mounts these next to the agents' commands.
"""

CORE_COMMANDS = (
    "spreadgym.commands.materials",
    "spreadgym.commands.calibrate",
    "spreadgym.commands.simulate",
    "spreadgym.commands.study",
)
