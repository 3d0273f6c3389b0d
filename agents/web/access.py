"""Who may talk to the app: the addresses it was started on, pages of its own origin.

The app has no accounts; what keeps other people out is where it listens (127.0.0.1
unless `serve --allow-remote` says otherwise) and two checks on every request, made
before anything else reads it (HTTP 403, one line):

* Host: the name the client used must be an address the server was started on. A web
  page elsewhere can point a name of its own at 127.0.0.1 (DNS rebinding) and then send
  requests that the browser treats as its own; they arrive with that name as their Host
  and are refused. Accepted: the listening address, and on loopback `localhost`,
  `127.0.0.1` and `::1`; on every interface (0.0.0.0 or ::), any IP address literal and
  this machine's own names.
* Origin (same-origin rule): a request a browser sends from a page carries the page's
  origin; it must be this server's own (`http://` and the Host), so no other site's page
  can start work here. A state-changing request (POST, DELETE) a browser marks as
  cross-site or same-site (Sec-Fetch-Site) is refused too, and a POST body must be JSON,
  which a cross-site form cannot send without asking the server first. Clients that are
  not browsers (curl, scripts) send no Origin and pass.
"""

from __future__ import annotations

import ipaddress
import socket
from dataclasses import dataclass
from typing import Optional

from starlette.responses import JSONResponse

LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")
WILDCARDS = ("0.0.0.0", "::")
SAFE_METHODS = ("GET", "HEAD", "OPTIONS")


def is_loopback(host: str) -> bool:
    """Whether `host` (an address or 'localhost') is this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class Addresses:
    """The address the server listens on and the names a client may use for it."""

    host: str = "127.0.0.1"

    @property
    def everywhere(self) -> bool:
        return self.host in WILDCARDS

    def names(self) -> set[str]:
        names = {self.host.lower()}
        if is_loopback(self.host) or self.everywhere:
            names.update(LOOPBACK_NAMES)
        if self.everywhere:
            names.update(n.lower() for n in (socket.gethostname(), socket.getfqdn()) if n)
        return names

    def allows(self, name: str) -> bool:
        """Whether a Host name (no port) is one of the server's."""
        name = name.lower().strip("[]")
        if name in self.names():
            return True
        if self.everywhere:
            try:
                ipaddress.ip_address(name)
                return True  # an address literal cannot be rebound to this machine by another site's name
            except ValueError:
                return False
        return False


def host_name(header: str) -> Optional[str]:
    """The host part of a Host header (`name`, `name:port`, `[v6]:port`); None if malformed."""
    header = header.strip()
    if not header or any(c.isspace() or c in "/@\\" for c in header):
        return None
    if header.startswith("["):
        end = header.find("]")
        rest = header[end + 1:]
        if end < 0 or (rest and not (rest.startswith(":") and rest[1:].isdigit())):
            return None
        return header[1:end]
    name, _, port = header.partition(":")
    if port and not port.isdigit():
        return None
    return name


class LocalOnly:
    """ASGI middleware: the Host and Origin checks of the module's docstring (403, one line)."""

    def __init__(self, app, addresses: Addresses):
        self.app, self.addresses = app, addresses

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        problem = self.problem(scope)
        if problem:
            return await JSONResponse({"error": problem}, status_code=403)(scope, receive, send)
        await self.app(scope, receive, send)

    def problem(self, scope) -> Optional[str]:
        """Why the request is refused, or None."""
        headers = {}
        for key, value in scope["headers"]:
            headers.setdefault(key.decode("latin-1").lower(), value.decode("latin-1"))
        host = headers.get("host", "")
        name = host_name(host)
        if name is None or not self.addresses.allows(name):
            return (f"Host {host[:100]!r} is not an address this server was started on "
                    f"({', '.join(sorted(self.addresses.names()))}); use one of those")
        origin = headers.get("origin")
        if origin is not None and origin.lower() != f"http://{host}".lower():
            return (f"Origin {origin[:100]!r} is another site: only pages of this server (http://{host}) may "
                    "send it requests")
        if scope["method"] not in SAFE_METHODS:
            site = headers.get("sec-fetch-site", "same-origin")
            if site not in ("same-origin", "none"):
                return f"a {site} request may not change anything here (Sec-Fetch-Site); use this server's pages"
            if scope["method"] == "POST":
                media = headers.get("content-type", "").split(";")[0].strip().lower()
                if media != "application/json":
                    return (f"content-type {media[:60] or 'missing'!r}: a request body here is JSON "
                            "(content-type: application/json)")
        return None
