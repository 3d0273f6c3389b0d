"""The layers read upwards only: config -> physics -> spread -> viz -> fit -> studies -> cli -> envs -> agents.

A module may import its own layer and the ones below it, never one above: the core
(spreadgym/) needs neither gymnasium nor the envs and agents, the envs never need the
agents, and nothing but the commands reads the studies. The package's `__init__`
registers the envs by string (gymnasium entry points) and is left out.
"""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = (  # lowest first; errors, report, threads, device and heap are plain helpers every layer may use
    ("spreadgym.errors", "spreadgym.report", "spreadgym.threads", "spreadgym.device", "spreadgym.heap"),
    ("spreadgym.config", "spreadgym.out_folder"),  # out_folder: the --out rule of every command
    ("spreadgym.physics",),
    ("spreadgym.spread",),
    ("spreadgym.viz",),
    ("spreadgym.fit",),  # fitting a scene to a tray test: runs the spread chain, draws with viz
    ("spreadgym.studies",),
    ("spreadgym.cli", "spreadgym.warm"),  # entry points: the commands, and the kernels' warm-up at install
    ("spreadgym.envs",),
    ("spreadgym.agents",),
)
FOLDERS = {"spreadgym": "spreadgym", "envs": "spreadgym.envs", "agents": "spreadgym.agents"}
CORE_TESTS = ("config", "physics", "spread", "viz", "fit", "studies", "cli")


def layer(module: str) -> int:
    for rank, prefixes in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return rank
    raise AssertionError(f"{module} belongs to no layer: add it to LAYERS")


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = [FOLDERS[rel.parts[0]], *rel.parts[1:]]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imported_modules(path: Path, package: str = "") -> set[str]:
    """Every module `path` imports, at the top or inside functions, relative imports resolved."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                names.add(".".join(base + ([node.module] if node.module else [])))
            elif node.module:
                names.add(node.module)
    return names


def sources():
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path != ROOT / "spreadgym" / "__init__.py":
                yield path


def test_the_layers_cover_every_module():
    for path in sources():
        layer(module_name(path))


def test_no_module_imports_a_layer_above_its_own():
    offenders = {}
    for path in sources():
        name = module_name(path)
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        upward = sorted(m for m in imported_modules(path, package)
                        if m.startswith("spreadgym.") and layer(m) > layer(name))
        if upward:
            offenders[str(path.relative_to(ROOT))] = upward
    assert offenders == {}


def test_core_modules_import_nothing_from_the_rl_stack():
    heavy = ("gymnasium", "stable_baselines3", "torch", "ray", "rl_zoo3")
    offenders = {}
    for path in sorted((ROOT / "spreadgym").rglob("*.py")):
        if path.name == "__init__.py" and path.parent.name == "spreadgym":
            continue
        found = sorted(m for m in imported_modules(path) if m.split(".")[0] in heavy)
        if found:
            offenders[str(path.relative_to(ROOT))] = found
    assert offenders == {}


@pytest.mark.parametrize("folder", CORE_TESTS)
def test_core_tests_import_nothing_from_envs_or_agents(folder):
    upper = ("spreadgym.envs", "spreadgym.agents", "gymnasium", "stable_baselines3")
    for path in sorted((ROOT / "tests" / folder).rglob("*.py")):
        assert not any(m.startswith(upper) for m in imported_modules(path)), path


def test_layer_ranks_are_read_off_real_imports():
    """The checks above would pass on an empty walk: make sure they see imports going down."""
    pipeline = imported_modules(ROOT / "spreadgym" / "spread" / "pipeline.py")
    assert "spreadgym.config.scene" in pipeline and layer("spreadgym.spread.pipeline") > layer("spreadgym.config")
    assert layer(module_name(ROOT / "envs" / "common" / "task.py")) == layer("spreadgym.envs")
    assert layer("spreadgym.agents.training") > layer("spreadgym.envs.common.task") > layer("spreadgym.studies.paper")


def test_core_runs_without_gymnasium_installed():
    code = (
        "import sys; sys.modules['gymnasium'] = None\n"
        "from spreadgym.config.scene import load_scene\n"
        "from spreadgym.spread.pipeline import run_scene\n"
        "m = run_scene(load_scene('paper', {'sim.granules': 50, 'feed.drop_height_m': 0.0,"
        " 'contact.vane_restitution': 0.0}), ci=False).metrics\n"
        "assert m.model == 'compiled' and 'gymnasium' not in [k for k, v in sys.modules.items() if v]\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
