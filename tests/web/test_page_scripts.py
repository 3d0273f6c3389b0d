"""The pages' scripts (agents/web/static, unchanged) run in node against a stand-in DOM and
fetch whose answers the scripts in tests/web/pages give late, out of order or as errors:
no answer for other inputs than those shown is ever shown as current (the pattern page's
drafts while a field is typed or a scene loads, the fit page's fits while its inputs change,
the chart page's clicks). Skipped where node is not installed (the browser tests need more)."""

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
NODE = shutil.which("node")


@pytest.mark.skipif(NODE is None, reason="node is not installed")
@pytest.mark.parametrize("script", ["pattern_stale.js", "fit_stale.js", "charts_race.js"])
def test_no_stale_answer_is_shown(script):
    command = [NODE, str(ROOT / "tests" / "web" / "pages" / script), str(ROOT / "agents" / "web" / "static")]
    done = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stdout + done.stderr
