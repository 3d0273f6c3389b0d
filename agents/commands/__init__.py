"""CLI subcommands of the agents layer (same protocol as spreadgym.commands)."""

AGENT_COMMANDS = (
    "spreadgym.agents.commands.train",
    "spreadgym.agents.commands.evaluate",
    "spreadgym.agents.commands.compare",
    "spreadgym.agents.commands.demo",
    "spreadgym.agents.commands.bench",
)
