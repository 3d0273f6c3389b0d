"""numba's kernel caches are dropped when any kernel source changes (numba issue #1833)."""

import re
from pathlib import Path

import spreadgym
from spreadgym.physics.compiled.kernel_cache import KERNEL_SOURCES, drop_stale_caches


def test_caches_go_when_a_called_kernel_changes_and_stay_otherwise(tmp_path):
    caller, callee = tmp_path / "caller.py", tmp_path / "callee.py"
    caller.write_text("def run(): return step()\n")
    callee.write_text("def step(): return 1\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    built = [cache / "caller.run-1.py311.nbi", cache / "caller.run-1.py311.0.nbc"]

    def build():
        for path in built:
            path.write_bytes(b"machine code")

    bytecode = cache / "caller.cpython-311.pyc"
    bytecode.write_bytes(b"python bytecode")
    build()
    assert drop_stale_caches([caller, callee])  # no stamp yet: nothing proves they are current
    assert not any(path.exists() for path in built)
    build()
    assert not drop_stale_caches([caller, callee])  # same sources: kept
    assert all(path.exists() for path in built)
    callee.write_text("def step(): return 2\n")  # only the called file changes
    assert drop_stale_caches([caller, callee])
    assert not any(path.exists() for path in built)
    assert bytecode.exists()  # Python's own caches are not numba's business


def test_every_kernel_source_is_watched():
    package = Path(spreadgym.__file__).parent
    compiling = {path.resolve() for path in package.rglob("*.py")
                 if re.search(r"^@(KERNEL|PARALLEL|INLINED|njit|cuda\.jit)\b", path.read_text(), re.MULTILINE)}
    assert len(compiling) > 10
    assert compiling <= {path.resolve() for path in KERNEL_SOURCES}
    assert all(path.is_file() for path in KERNEL_SOURCES)
