"""The policy shipped for the paper scene (configs/policies/paper/): it loads, it is a
SpinnerDesign policy of the paper chart's contexts, `--method policy` takes it without
`--policy` (which still overrides it), and a scene with none shipped is one line, exit 2."""

import hashlib
import json
import shutil

import gymnasium
import numpy as np
import pytest

from spreadgym.agents.chart import make_spec, runner
from spreadgym.agents.chart.policy import propose, shipped_policy
from spreadgym.agents.chart.spec import cell_seed, resolve_fertilizers
from spreadgym.agents.training import load_policy
from spreadgym.cli.main import main
from spreadgym.config.materials import load_library
from spreadgym.config.resources import config_dir
from spreadgym.config.scene import load_scene
from spreadgym.errors import SpreadgymError

SHIPPED = config_dir() / "policies" / "paper"
MAX_BYTES = 500_000  # a 64x64 MLP and its optimiser state: about 160 kB


def test_the_shipped_policy_is_a_small_spinner_design_policy_of_the_paper_charts_contexts():
    zipped = SHIPPED / "model.zip"
    assert zipped.stat().st_size < MAX_BYTES
    assert "spreadgym train --algo ppo" in (SHIPPED / "README.md").read_text(encoding="utf-8")
    policy = load_policy(SHIPPED)
    assert policy.env_id.endswith("SpinnerDesign-v0")
    env = gymnasium.make(policy.env_id, **policy.env_kwargs).unwrapped
    assert env.task.base_scene.name == "paper"
    charted = resolve_fertilizers("all", load_scene("paper"), load_library())[0]
    assert {"compound-10-16-10", "pellet"} <= set(env.task.cfg.context.fertilizers) & set(charted)
    spec, notes = make_spec("paper", "all", "3", method="policy")
    assert set(spec.fertilizers) == set(charted) & set(env.task.cfg.context.fertilizers)
    assert any("potassium-chloride left out: the policy was trained without it" in n for n in notes)
    with pytest.raises(SpreadgymError, match="--fertilizers potassium-chloride: the policy .* was trained without it"):
        make_spec("paper", "potassium-chloride", "3", method="policy")
    low, high = env.task.cfg.context.target_swath_m
    assert low <= 3.0 and high >= 6.0


def test_method_policy_takes_the_shipped_policy_and_policy_overrides_it(tmp_path):
    spec = make_spec("paper", "all", "3:6:0.5", method="policy")[0]
    assert spec.policy == str(SHIPPED / "model.zip")
    assert spec.policy_sha256 == hashlib.sha256((SHIPPED / "model.zip").read_bytes()).hexdigest()
    units = [propose(spec, cell, cell_seed(spec.seed, cell).spawn(5)[4]) for cell in spec.cells]
    assert all(u.shape == (2,) and np.all(np.abs(u) <= 1.0) for u in units)
    assert len({tuple(u) for u in units}) == len(units)  # the proposal follows the fertilizer and the width
    copy = tmp_path / "mine"
    shutil.copytree(SHIPPED, copy)
    assert make_spec("paper", "pellet", "3", method="policy+search", policy=str(copy))[0].policy == str(
        copy / "model.zip")


def test_the_command_without_policy_runs_the_shipped_one(monkeypatch, tmp_path, capsys):
    seen = {}

    def fake_run_chart(spec, out, **kwargs):  # the chart's work is tested elsewhere: here the spec the CLI made
        seen["spec"] = spec
        return runner.ChartResult(spec, {"policy": spec.policy}, [])

    monkeypatch.setattr(runner, "run_chart", fake_run_chart)
    code = main(["chart", "--scene", "paper", "--fertilizers", "all", "--widths", "3:6:0.5", "--method", "policy",
                 "--verify-model", "compiled", "--out", str(tmp_path / "c"), "--json"])
    assert code == 0 and json.loads(capsys.readouterr().out)["policy"] == str(SHIPPED / "model.zip")
    assert (seen["spec"].method, seen["spec"].verify_model) == ("policy", "compiled")


@pytest.mark.parametrize("method", ["policy", "policy+search"])
def test_a_scene_without_a_shipped_policy_needs_policy_in_one_line(method, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["chart", "--scene", "field", "--fertilizers", "pellet", "--widths", "4", "--method", method,
                 "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and not out.exists()
    assert err[0].startswith(f"spreadgym chart: error: --policy: needed by --method {method} on scene 'field': "
                             "no policy is shipped")
    assert "(shipped: paper)" in err[0] and "Traceback" not in err[0]
    with pytest.raises(SpreadgymError, match="--policy: needed by"):
        shipped_policy(load_scene("field"), method)
