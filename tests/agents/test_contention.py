"""The contention probe (agents/contention.py): its phases do not overlap, its rates are
divided by one process's, its arithmetic is real work, and a round runs end to end."""

import time

import pytest

from spreadgym.agents import contention


def test_phases_follow_one_another_with_a_pause_and_the_batches_twice_as_long():
    windows = contention.phase_windows(100.0, 4.0)
    assert list(windows) == ["arithmetic", "memory", "batches"]
    assert windows["arithmetic"] == (100.0, 104.0)
    assert windows["memory"][0] == pytest.approx(104.0 + contention.PAUSE_S)
    assert windows["batches"][1] - windows["batches"][0] == pytest.approx(8.0)


def test_rates_are_divided_by_one_process_alone():
    def process(scale, late=False):
        return {"arithmetic": 100.0 * scale, "memory": 10.0 * scale, "spinner": 80.0 * scale,
                "finish": 160.0 * scale, "late": late, "ready_s": 1.0}

    rows = contention.summarise({1: [process(1.0)], 4: [process(0.6), process(0.7), process(0.8, late=True),
                                                         process(0.9)]})
    four = {r["probe"]: r for r in rows if r["procs"] == 4}
    assert four["spinner"]["per_process_over_one"] == pytest.approx(0.75)  # median of 0.6..0.9
    assert four["memory"]["total"] == pytest.approx(30.0)
    assert four["finish"]["low"] == pytest.approx(96.0)
    assert four["arithmetic"]["late_starts"] == 1
    assert all(r["per_process_over_one"] == 1.0 for r in rows if r["procs"] == 1)


def test_the_arithmetic_takes_time_in_proportion_to_its_rounds():
    contention.arithmetic(10)  # compiled
    times = {}
    for steps in (200_000, 2_000_000):
        began = time.perf_counter()
        contention.arithmetic(steps)
        times[steps] = time.perf_counter() - began
    assert times[2_000_000] > 4.0 * times[200_000]  # not folded into a closed form by the compiler


def test_a_round_of_one_process_reports_every_probe(tmp_path):
    rows = contention.measure(tmp_path, [1], phase_s=0.3, stream_mb=8, designs=1, start_s=4.0, say=lambda _: None)
    assert {r["probe"] for r in rows} == set(contention.PROBES)
    assert all(r["processes_reported"] == 1 and r["per_process"] > 0.0 for r in rows)
    assert (tmp_path / "contention.csv").read_text().startswith("procs,probe,unit")
