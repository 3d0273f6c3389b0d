"""`spreadgym bench`: every section it lists runs something, and every runner is listed."""

import argparse
from pathlib import Path

from spreadgym.agents.commands import bench


def test_every_section_has_a_runner_and_every_runner_a_section(tmp_path: Path):
    runners = bench.section_runners(argparse.Namespace(out=tmp_path, repeats=1), print)
    assert list(runners) == list(bench.SECTIONS)  # make bench runs them all, in this order


def test_only_accepts_every_section(tmp_path: Path):
    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    for name in bench.SECTIONS:
        assert parser.parse_args(["--only", name, "--out", str(tmp_path)]).only == [name]
