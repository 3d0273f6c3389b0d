"""The chart scale benchmark's bookkeeping on a tiny chart: rates, efficiency against the
1-worker baseline, and the same rows on 1 and 2 local workers."""

import pytest

from spreadgym.agents.chart import scale

TINY = dict(scene="paper", fertilizers="compound-10-16-10", widths="3,4", budget=1, granules=64,
            search_model="analytic", verify_runs=2)


@pytest.mark.slow  # starts Ray twice
def test_scale_rows_on_one_and_two_local_workers(tmp_path):
    configs = (("1 worker", 1, lambda: scale._local(1)), ("2 workers", 2, lambda: scale._local(2)))
    rows = scale.chart_scale_rows(repeats=1, chart=TINY, configs=configs)
    assert [r["configuration"] for r in rows] == ["1 worker", "2 workers"]
    assert all(r["cells"] == 2 and r["same_rows_as_first_run"] for r in rows)
    assert rows[0]["parallel_efficiency"] == pytest.approx(1.0)
    expected = rows[1]["cells_per_min"] / (2 * rows[0]["cells_per_min"])
    assert rows[1]["parallel_efficiency"] == pytest.approx(expected)
    assert all(r["cells_per_min_low"] <= r["cells_per_min"] <= r["cells_per_min_high"] for r in rows)
    assert scale.plot_chart_scale(rows, tmp_path / "scale.png").stat().st_size > 0
