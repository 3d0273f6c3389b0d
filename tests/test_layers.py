"""The three layers: agents -> envs -> spreadgym; the core never needs gymnasium."""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CORE = sorted(p for p in (ROOT / "spreadgym").rglob("*.py") if p.name != "__init__.py" or p.parent.name != "spreadgym")


def imported_modules(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_core_modules_import_nothing_from_the_upper_layers():
    upward = ("gymnasium", "stable_baselines3", "torch", "spreadgym.envs", "spreadgym.agents")
    offenders = {
        str(path.relative_to(ROOT)): sorted(n for n in imported_modules(path) if n.startswith(upward))
        for path in CORE
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_envs_import_nothing_from_agents():
    for path in (ROOT / "envs").rglob("*.py"):
        assert not any(n.startswith(("spreadgym.agents", "stable_baselines3")) for n in imported_modules(path)), path


def test_core_runs_without_gymnasium_installed():
    code = (
        "import sys; sys.modules['gymnasium'] = None\n"
        "from spreadgym.config.scene import load_scene\n"
        "from spreadgym.spread.pipeline import run_scene\n"
        "m = run_scene(load_scene('paper', {'sim.granules': 50, 'feed.drop_height_m': 0.0,"
        " 'contact.vane_restitution': 0.0}), ci=False).metrics\n"
        "assert m.model == 'analytic' and 'gymnasium' not in [k for k, v in sys.modules.items() if v]\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
