"""Shared fixtures: the material library, small fast scenes, numba's CUDA simulator."""

import json
import os
import subprocess
import sys
from typing import Optional

import pytest

from spreadgym.config.materials import load_library
from spreadgym.physics.contacts import resolve_contacts
from spreadgym.physics.granules import sample_granules


@pytest.fixture(scope="session")
def library():
    return load_library()


@pytest.fixture
def prepare(library):
    """(granules, contacts) for a scene, sampled with the scene's seed."""

    def _prepare(scene):
        granules = sample_granules(scene, library.fertilizer_of(scene))
        return granules, resolve_contacts(scene, library)

    return _prepare


@pytest.fixture(autouse=True)
def _default_thread_count():
    """A command run in a test (`--threads N`) sets the process's thread count (and device): put them back."""
    yield
    from spreadgym.device import set_device
    from spreadgym.threads import set_threads

    set_threads(None)
    set_device(None)


@pytest.fixture
def cuda_simulator():
    """Run a script in a fresh interpreter under numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1,
    read when numba's CUDA target loads), with `args` and `env` added to its command line
    and environment, and return the JSON it prints last (None where it prints none)."""

    def _run(script: str, args: tuple = (), env: Optional[dict] = None) -> Optional[dict]:
        full = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1", **(env or {})}
        full.pop("SPREADGYM_DEVICE", None)
        done = subprocess.run([sys.executable, "-c", script, *args], capture_output=True, text=True, timeout=900,
                              env=full)
        assert done.returncode == 0, done.stderr[-3000:]
        lines = done.stdout.strip().splitlines()
        return json.loads(lines[-1]) if lines and lines[-1].startswith("{") else None

    return _run


GPU_LAUNCH_LOGGER = """
import os
if os.environ.get("SPREADGYM_TEST_LAUNCH_LOG"):
    from spreadgym.physics.compiled import cuda_spinner

    def _logged(module, name, kind):
        call = getattr(module, name)

        def logged(*args, **kwargs):
            with open(os.environ["SPREADGYM_TEST_LAUNCH_LOG"], "a") as log:
                log.write(f"{os.getpid()} {kind}\\n")
            return call(*args, **kwargs)

        setattr(module, name, logged)

    _logged(cuda_spinner, "run_all", "spinner")
"""


@pytest.fixture
def gpu_launch_log(tmp_path):
    """(env, launches): `env` for a `cuda_simulator` script makes it and every process it
    starts (spawned or forked workers included) log each GPU launch of the spinner,
    through a sitecustomize on PYTHONPATH; `launches()` gives {kind: set of process ids
    that launched it}."""
    folder = tmp_path / "launch-logger"
    folder.mkdir()
    (folder / "sitecustomize.py").write_text(GPU_LAUNCH_LOGGER)
    log = tmp_path / "launches.txt"
    path = os.pathsep.join(p for p in (str(folder), os.environ.get("PYTHONPATH", "")) if p)
    env = {"PYTHONPATH": path, "SPREADGYM_TEST_LAUNCH_LOG": str(log)}

    def launches() -> dict:
        found: dict = {}
        for line in (log.read_text().splitlines() if log.exists() else []):
            pid, kind = line.split()
            found.setdefault(kind, set()).add(int(pid))
        return found

    return env, launches


def _listening_sockets(root: int) -> list[tuple[str, int, str, bool]]:
    """(address, port, process name, loopback) of every listening TCP socket held by
    process `root` or its descendants, read from /proc (net/tcp and tcp6 for the sockets
    in LISTEN state, each process's fd links for whose they are)."""
    import ipaddress
    import os

    from spreadgym.agents.web.stress import tree

    listening = {}
    for table, width in (("tcp", 4), ("tcp6", 16)):
        try:
            with open(f"/proc/net/{table}", encoding="ascii") as handle:
                lines = handle.read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if fields[3] != "0A":  # TCP_LISTEN
                continue
            address, port = fields[1].split(":")
            raw = bytes.fromhex(address)
            raw = b"".join(raw[i:i + 4][::-1] for i in range(0, width, 4))  # host-order words
            ip = ipaddress.ip_address(raw)
            mapped = getattr(ip, "ipv4_mapped", None)
            listening[int(fields[9])] = (str(ip), int(port, 16), ip.is_loopback or bool(mapped and mapped.is_loopback))
    found = []
    for pid in tree(root):
        try:
            links = []
            for fd in os.listdir(f"/proc/{pid}/fd"):
                try:
                    links.append(os.readlink(f"/proc/{pid}/fd/{fd}"))
                except OSError:  # closed meanwhile
                    pass
            with open(f"/proc/{pid}/comm", encoding="utf-8") as handle:
                comm = handle.read().strip()
        except OSError:
            continue
        for link in links:
            if link.startswith("socket:[") and int(link[8:-1]) in listening:
                address, port, loopback = listening[int(link[8:-1])]
                found.append((address, port, comm, loopback))
    return found


@pytest.fixture
def listening_sockets():
    """The listening sockets of a process tree: `listening_sockets(pid)` -> [(address, port, name)]."""
    return _listening_sockets



@pytest.fixture
def copied_fertilizer(tmp_path):
    """A user's materials file whose one fertilizer, "my-compound", is the library's
    compound-10-16-10 value for value (the YAML anchors resolved, provenance left out):
    `(path, name)`. What runs it must match what runs the compound."""
    import yaml

    from spreadgym.config.resources import config_dir, read_yaml

    entry = dict(read_yaml(config_dir() / "materials.yaml")["fertilizers"]["compound-10-16-10"])
    entry.pop("provenance")
    path = tmp_path / "my-materials.yaml"
    path.write_text(yaml.safe_dump({"fertilizers": {"my-compound": entry}}))
    return path, "my-compound"
