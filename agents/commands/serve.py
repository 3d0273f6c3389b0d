"""`spreadgym serve`: the local web app (pattern page, chart page) on uvicorn.

FastAPI and uvicorn are imported only when the command runs, so the console script
stays quick for every other command.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from spreadgym.cli import arguments

DEFAULT_HOST = "127.0.0.1"  # this machine only, unless --host says otherwise
DEFAULT_PORT = 8050


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", default=DEFAULT_HOST,
                        help=f"address to listen on (default {DEFAULT_HOST}: this machine only)")
    parser.add_argument("--port", type=arguments.integer(1, 65535), default=DEFAULT_PORT,
                        help=f"port (default {DEFAULT_PORT})")
    parser.add_argument("--charts", type=Path, default=Path("out/charts"), metavar="DIR",
                        help="chart folders the chart page shows and where its jobs write (default out/charts)")


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from spreadgym.agents.web.app import create_app

    print(f"spreadgym serve: http://{args.host}:{args.port}/ (charts under {args.charts}; Ctrl-C stops)")
    uvicorn.run(create_app(args.charts), host=args.host, port=args.port, log_level="warning")
    return 0
