"""Tray tests as hostile input (issue 44): any layout, separator, unit, size or value is
read or refused in one line naming its line, and a fit of a layout the model cannot
describe is refused in one line, each within its own time and memory cap."""

import math
import os

import numpy as np
import pytest
from conftest import bounded
from hypothesis import given
from hypothesis import strategies as st

from spreadgym.config.scene import load_scene
from spreadgym.errors import SpreadgymError
from spreadgym.fit.run import fit_tray_test
from spreadgym.fit.space import parse_fit_specs
from spreadgym.fit.trays import MAX_TRAYS, TrayTest, parse_trays, read_trays

HEADERS = st.sampled_from([("x_m", "mass_g"), ("x [m]", "mass (g)"), ("x_cm", "mass_kg"), ("x (mm)", "mass [mg]"),
                           ("X_M", "Mass_G"), ("x", "mass"), ("pos_m", "mass_g"), ("x_m", "mass_lb")])
NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30),
                    st.sampled_from(["1,5", "1.234,5", "", " ", "1e-320", "-0", "0x10", "1_000", "nan", "∞"]))


def _cell(value, decimal_comma: bool) -> str:
    text = str(value)
    return text.replace(".", ",") if decimal_comma and isinstance(value, float) else text


@given(header=HEADERS, separator=st.sampled_from([",", ";", "\t"]), decimal_comma=st.booleans(),
       rows=st.lists(st.tuples(NUMBERS, NUMBERS), max_size=40), width=st.sampled_from([0.05, 0.5, 1.0, 5.0]))
def test_any_tray_file_is_read_or_refused_in_one_line(header, separator, decimal_comma, rows, width):
    text = separator.join(header) + "\n" + "".join(
        f"{_cell(x, decimal_comma and separator != ',')}{separator}{_cell(m, decimal_comma and separator != ',')}\n"
        for x, m in rows)
    with bounded(10):
        try:
            test = parse_trays(text, width)
        except SpreadgymError as exc:
            message = str(exc)
            assert message.startswith("--trays: ") and "\n" not in message and len(message) < 400, message
            return
    assert test.count >= 5 and np.all(np.isfinite(test.x_m)) and np.all(test.mass_kg >= 0)
    assert np.all(np.abs(test.x_m) <= 200.0)


@given(layout=st.lists(st.floats(-150, 150, allow_nan=False), min_size=5, max_size=60, unique=True),
       width=st.sampled_from([0.05, 0.25, 0.5]))
def test_any_layout_of_trays_parses_exactly_where_no_two_trays_of_a_pass_overlap(layout, width):
    x = np.round(np.array(layout), 6)
    text = "x_m,mass_g\n" + "".join(f"{float(v)!r},{1 + i % 7}\n" for i, v in enumerate(x))
    gaps = np.diff(np.sort(x))
    try:
        test = parse_trays(text, width)
    except SpreadgymError as exc:
        assert ("overlap" in str(exc) or "given twice" in str(exc)) and np.min(gaps) < width * (1 - 1e-6)
        return
    assert np.min(gaps) >= width * (1 - 1e-6) and sorted(test.x_m.tolist()) == sorted(x.tolist())


def _fit(test: TrayTest, granules: int = 256):
    scene = load_scene("paper", {"granule.rotation": "locked"})
    return fit_tray_test(scene, parse_fit_specs(["contact.vane_restitution=0.3:0.7"], scene), test, granules=granules)


def _pattern(x: np.ndarray) -> np.ndarray:
    return 1e-3 * np.clip(30.0 - 8.0 * np.abs(x), 0.0, None)


@pytest.mark.parametrize("case", ["4000 trays of 0.05 m", "two trays 199 m away", "1 g trays out to 200 m",
                                  "offset 9 m", "a subnormal catch", "a named pipe", "a device"])
def test_a_hostile_layout_is_a_result_or_one_line_within_10_s_and_1_gib(case, tmp_path):
    local = np.arange(-16, 17) * 0.25
    with bounded(10 if case != "4000 trays of 0.05 m" else 30):
        try:
            if case == "4000 trays of 0.05 m":
                x = (np.arange(MAX_TRAYS) - MAX_TRAYS // 2) * 0.05
                result = _fit(TrayTest(x, _pattern(x), np.zeros(x.size, np.int64), 0.05, case))
                assert math.isfinite(result.estimate[0]) and result.model.trays > 100
                return
            if case == "two trays 199 m away":
                x = np.concatenate([local, [-199.0, 199.0]])
                result = _fit(TrayTest(x, np.concatenate([_pattern(local), [0.0, 0.0]]), np.zeros(x.size, np.int64),
                                       0.25, case))
                assert math.isfinite(result.estimate[0])
                return
            if case == "1 g trays out to 200 m":
                far = np.concatenate([np.arange(-200.0, -5.0, 0.5), np.arange(5.5, 200.5, 0.5)])
                x = np.concatenate([local, far])
                _fit(TrayTest(x, np.concatenate([_pattern(local), np.full(far.size, 1e-3)]),
                              np.zeros(x.size, np.int64), 0.25, case))
            elif case == "offset 9 m":
                _fit(TrayTest(local + 9.0, _pattern(local), np.zeros(local.size, np.int64), 0.25, case))
            elif case == "a subnormal catch":
                parse_trays("x_m,mass_g\n" + "".join(f"{v},{m * 1e3}\n" for v, m in zip(local, _pattern(local)))
                            + "5.0,1e-320\n", 0.25)
            elif case == "a named pipe":
                os.mkfifo(tmp_path / "pipe")
                read_trays(tmp_path / "pipe", 0.25)
            else:
                read_trays("/dev/zero", 0.25)
        except SpreadgymError as exc:
            assert "\n" not in str(exc) and str(exc).startswith("--trays: "), str(exc)
            return
    raise AssertionError(f"{case}: neither a result nor a refusal")
