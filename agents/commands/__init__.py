"""Subcommands of the agents layer; `spreadgym.cli.main` names them by string."""
