"""Start-up: a command imports only what it uses (not a timing test).

Each command runs in a fresh interpreter, as the console script would, and reports the
heavy modules it loaded: a simulate without --plot draws nothing (no matplotlib), no
core command makes an env (no gymnasium) or trains (no torch), and none loads Ray,
scipy.stats (~0.25 s) or scipy.integrate (~0.1 s, the flight's ODE reference only).
"""

import json
import subprocess
import sys

import pytest

from spreadgym.cli import COMMANDS

HEAVY = ("gymnasium", "matplotlib", "torch", "ray", "scipy.stats", "scipy.integrate", "optuna", "stable_baselines3")
PROBE = """
import contextlib, io, json, sys
from spreadgym.cli.main import main
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
    code = main(sys.argv[1:])
print(json.dumps({"code": code, "heavy": [m for m in HEAVY if m in sys.modules]}))
"""


def loaded(*argv: str) -> dict:
    script = f"HEAVY = {HEAVY!r}\n" + PROBE
    done = subprocess.run([sys.executable, "-c", script, *argv], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("argv", [
    ("simulate", "--scene", "paper", "--json", "--set", "sim.granules=256"),
    ("simulate", "--scene", "paper-deflectors", "--set", "sim.granules=256"),
    ("reference", "--scene", "paper", "--replicates", "4", "--granules", "128", "--json"),
    ("materials",),
    ("--help",),
])
def test_core_commands_load_no_heavy_module(argv):
    result = loaded(*argv)
    assert result["code"] == 0
    assert result["heavy"] == []


def test_importing_the_package_loads_no_gymnasium_yet_registers_the_envs_once_it_is_imported():
    script = ("import sys, spreadgym; assert 'gymnasium' not in sys.modules\n"
              "import gymnasium; print(sorted(i for i in gymnasium.registry if 'SpinnerDesign' in i))")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "spreadgym/SpinnerDesign-v0" in done.stdout and "spreadgym:SpinnerDesign-v0" in done.stdout


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_every_help_text_prints(command, capsys):
    """argparse formats help strings with %: a bare one (say '90 %') crashes --help."""
    from spreadgym.cli.main import main

    assert main(["--help"] if command is None else [command, "--help"]) == 0
    assert "usage: spreadgym" in capsys.readouterr().out
