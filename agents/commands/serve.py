"""`spreadgym serve`: the local web app (pattern page, chart page, fit page) on uvicorn.

It listens on 127.0.0.1: this machine only. Another address needs `--allow-remote`, and
the command then says what it exposes (there are no accounts). The socket is bound here,
before uvicorn starts, so a busy port or an address the machine does not have is one
line (exit 2). SIGTERM or Ctrl-C stops it within a few seconds: open requests get
GRACE_S to finish, then the worker processes and a running chart job are stopped.

FastAPI and uvicorn are imported only when the command runs, so the console script
stays quick for every other command.
"""

from __future__ import annotations

import argparse
import ipaddress
import json
import socket
from pathlib import Path

from spreadgym.cli import arguments
from spreadgym.config.materials import user_materials
from spreadgym.errors import SpreadgymError

DEFAULT_HOST = "127.0.0.1"  # this machine only, unless --host and --allow-remote say otherwise
DEFAULT_PORT = 8050
GRACE_S = 2.0  # after SIGTERM, open requests get this long before their work is stopped


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from spreadgym.agents.web.app import TIME_LIMIT_S

    parser.add_argument("--host", default=DEFAULT_HOST,
                        help=f"address to listen on (default {DEFAULT_HOST}: this machine only; any other needs "
                             "--allow-remote)")
    parser.add_argument("--allow-remote", action="store_true",
                        help="let --host be an address other machines reach (no login: whoever reaches the port "
                             "can run simulations and fits and start chart jobs)")
    parser.add_argument("--port", type=arguments.integer(1, 65535), default=DEFAULT_PORT,
                        help=f"port (default {DEFAULT_PORT})")
    arguments.add_materials_flag(parser)
    parser.add_argument("--charts", type=arguments.output_folder, default=Path("out/charts"), metavar="DIR",
                        help="chart folders the chart page shows and where its jobs write (default out/charts)")
    parser.add_argument("--time-limit", type=arguments.real(1.0, 86400.0), default=TIME_LIMIT_S, metavar="S",
                        help=f"a simulation's or fit's wait and work, at most S seconds (default {TIME_LIMIT_S:g})")


def listening_socket(host: str, port: int, allow_remote: bool) -> socket.socket:
    """The bound socket (checked: loopback unless `allow_remote`; the port free)."""
    from spreadgym.agents.web.access import is_loopback

    address = "127.0.0.1" if host == "localhost" else host
    try:
        ip = ipaddress.ip_address(address)
    except ValueError:
        raise SpreadgymError(f"--host {host!r}: not an IP address (or localhost)") from None
    if not is_loopback(address) and not allow_remote:
        raise SpreadgymError(f"--host {host}: not a loopback address; add --allow-remote to serve other machines "
                             "(there is no login: anyone who reaches the port can start work)")
    sock = socket.socket(socket.AF_INET6 if ip.version == 6 else socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((address, port))
    except OSError as exc:
        sock.close()
        raise SpreadgymError(f"--port {port}: cannot listen on {host}:{port} ({exc.strerror or exc}); "
                             "is another server there? choose another --port") from None
    sock.set_inheritable(True)
    return sock


def exposure(host: str, port: int, charts: Path) -> str:
    """What --allow-remote opens, for the terminal."""
    return (f"spreadgym serve: listening on {host}:{port} for other machines too (--allow-remote). There is no "
            "login: whoever reaches this port can run simulations and fits on this machine, start and cancel "
            f"chart jobs that write under {charts}, and read every chart there. Use it on a network you trust.")


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from spreadgym.agents.web.access import Addresses, is_loopback
    from spreadgym.agents.web.app import create_app

    sock = listening_socket(args.host, args.port, args.allow_remote)
    if not is_loopback(args.host):
        print(exposure(args.host, args.port, args.charts))
    print(f"spreadgym serve: http://{args.host}:{args.port}/ (charts under {args.charts}; Ctrl-C stops)", flush=True)
    app = create_app(args.charts, Addresses("127.0.0.1" if args.host == "localhost" else args.host), args.time_limit)
    config = uvicorn.Config(app, log_level="warning", http=JsonErrorsProtocol(), timeout_graceful_shutdown=GRACE_S)
    server = uvicorn.Server(config)
    exit_server = server.handle_exit

    def handle_exit(sig, frame) -> None:  # SIGTERM, Ctrl-C: the running work answers 503 at once, workers killed
        app.state.stop_work()
        exit_server(sig, frame)

    server.handle_exit = handle_exit
    with user_materials(args.materials):  # the whole server's library: its workers and chart jobs inherit it
        server.run(sockets=[sock])
    return 0


def JsonErrorsProtocol():  # noqa: N802 (a class made when uvicorn is imported)
    """uvicorn's HTTP/1.1 protocol whose own answer to a request it cannot parse (a
    malformed Content-Length or header) is JSON, like every answer of the app."""
    import h11
    from uvicorn.protocols.http.h11_impl import H11Protocol

    class Protocol(H11Protocol):
        def send_400_response(self, msg: str) -> None:
            body = json.dumps({"error": f"request: not valid HTTP ({msg.rstrip('.')}: a malformed request line "
                                        "or header, such as Content-Length)"}).encode()
            headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                       (b"connection", b"close")]
            for event in (h11.Response(status_code=400, headers=headers, reason=b"Bad Request"), h11.Data(data=body),
                          h11.EndOfMessage()):
                self.transport.write(self.conn.send(event))
            self.transport.close()

    return Protocol
