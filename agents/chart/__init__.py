"""Spreading charts: for each fertilizer and working width, the settings that spread it
most evenly, searched on the fast model and verified with the full one (`chart`, the
function `spreadgym chart` calls)."""

from spreadgym.agents.chart.runner import ChartResult, chart, run_chart
from spreadgym.agents.chart.spec import Cell, ChartSpec, make_spec

__all__ = ["Cell", "ChartResult", "ChartSpec", "chart", "make_spec", "run_chart"]
