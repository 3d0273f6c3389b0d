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


def test_a_section_whose_rows_differ_in_keys_writes_every_key(tmp_path: Path):
    """The web section's plate row alone has `aborted_requests`: the CSV took the first row's
    keys and refused the rest (ValueError), losing the section's figures after its run."""
    import csv

    rows = [{"measure": "page load", "median_s": 1.0},
            {"measure": "plate drag", "median_s": 2.0, "aborted_requests": 3}]
    bench.write_csv(rows, tmp_path / "web.csv")
    with open(tmp_path / "web.csv", newline="", encoding="utf-8") as handle:
        read = list(csv.DictReader(handle))
    assert read == [{"measure": "page load", "median_s": "1.0", "aborted_requests": ""},
                    {"measure": "plate drag", "median_s": "2.0", "aborted_requests": "3"}]
