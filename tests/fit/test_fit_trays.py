"""The tray file: what it accepts and the one-line errors (with line numbers) for what it does not."""

import numpy as np
import pytest

from spreadgym.config.scene import load_scene
from spreadgym.errors import SpreadgymError
from spreadgym.fit.likelihood import PatternModel
from spreadgym.fit.space import parse_fit_specs
from spreadgym.fit.trays import MAX_FILE_BYTES, TrayTest, parse_trays, read_trays, write_trays

GOOD = "# a comment\nx_m,mass_g\n-1.0,2\n-0.5,3\n0,4\n# between rows\n0.5,3.5\n1.0,1.5\n\n1.5,0\n"


def test_good_file_parses_to_si():
    test = parse_trays(GOOD, 0.5)
    np.testing.assert_allclose(test.x_m, [-1.0, -0.5, 0.0, 0.5, 1.0, 1.5])
    np.testing.assert_allclose(test.mass_kg, [2e-3, 3e-3, 4e-3, 3.5e-3, 1.5e-3, 0.0])
    assert test.lane.tolist() == [0] * 6


def test_pass_column_and_round_trip(tmp_path):
    text = "x_m,mass_g,pass\n" + "".join(f"{x},{1 + i},{j}\n" for j in (-1, 0, 1) for i, x in enumerate(
        (-1.0, -0.5, 0.0, 0.5, 1.0)))
    test = parse_trays(text, 0.5)
    assert sorted(set(test.lane.tolist())) == [-1, 0, 1]
    again = read_trays(write_trays(tmp_path / "t.csv", test, "round trip"), 0.5)
    np.testing.assert_allclose(again.mass_kg, test.mass_kg)
    assert again.lane.tolist() == test.lane.tolist()


@pytest.mark.parametrize("text, expected", [
    ("x_m,mass\n0,1\n", "line 1: unknown column 'mass'"),
    ("x_m\n0\n", "line 1: missing column mass_g"),
    ("# only\n", "no header line"),
    ("x_m,mass_g\n0,1\n0.5,-2\n1,1\n1.5,1\n2,1\n", "line 3: mass_g -2 is negative"),
    ("x_m,mass_g\n0,1\n0.5,nan\n1,1\n1.5,1\n2,1\n", "line 3: mass_g 'nan' is not finite"),
    ("x_m,mass_g\n0,1\n0.5,inf\n1,1\n1.5,1\n2,1\n", "line 3: mass_g 'inf' is not finite"),
    ("x_m,mass_g\n0,1\n0.5,abc\n", "line 3: mass_g 'abc' is not a number"),
    ("x_m,mass_g\n0,1\n0.7,1\n1,1\n1.5,1\n2,1\n", "line 3: x_m 0.7 is off the tray grid"),
    ("x_m,mass_g\n0,1\n0.5,1\n0.5,2\n1.5,1\n2,1\n", "line 4: tray x_m = 0.5 m of pass 0 is given twice (also line 3)"),
    ("x_m,mass_g\n0,1\n0.5,1\n1,1\n1.5,1\n", "line 5: 4 trays; allowed: at least 5"),
    ("x_m,mass_g\n0,1\n0.5,1\n1,0\n1.5,0\n2,0\n", "line 6: 2 trays caught anything; at least 5 must"),
    ("x_m,mass_g\n0,1,3\n", "line 2: 3 values for 2 columns"),
    ("x_m,mass_g\n0,1\n1,1\n2,1\n3,1\n5,1\n", "line 1: the closest trays are 1 m apart but pattern.tray_width_m"),
    ("x_m,mass_g,pass\n0,1,a\n", "line 2: pass 'a' is not a whole number"),
])
def test_bad_files_give_one_line_with_the_line_number(text, expected):
    with pytest.raises(SpreadgymError) as info:
        parse_trays(text, 0.5)
    message = str(info.value)
    assert expected in message and "\n" not in message


def test_file_size_is_capped(tmp_path):
    path = tmp_path / "big.csv"
    path.write_text("x_m,mass_g\n" + "0,1\n" * (MAX_FILE_BYTES // 4 + 1))
    with pytest.raises(SpreadgymError, match="bytes; allowed: at most"):
        read_trays(path, 0.5)


def test_other_passes_map_onto_the_single_pass():
    """Pass j drove along x = jW; for back-and-forth the odd passes run the other way, so
    their trays see the single pass mirrored: every pass's rows must map onto the same
    simulated trays as the matching rows of pass 0."""
    scene = load_scene("field", {"sim.granules": 256})  # back-and-forth, W = 5 m
    space = parse_fit_specs(["contact.vane_restitution=0.3:0.5"], scene)
    local = np.arange(-6, 7) * 0.5
    width = scene.pattern.target_swath_m
    x = np.concatenate([local, local + width, -local - width])  # pass 1 mirrored, pass -1 mirrored
    lanes = np.repeat([0, 1, -1], local.size)
    test = TrayTest(x, np.full(x.size, 1e-3), lanes, 0.5, "three passes")
    model = PatternModel(scene, space, test)
    pass0 = model.local_index[:local.size]
    assert model.local_index[local.size:2 * local.size].tolist() == (-pass0).tolist()
    assert model.local_index[2 * local.size:].tolist() == pass0.tolist()
    prediction = model.predict([[0.5]])[0]
    mirrored = prediction.log_mu[local.size:2 * local.size]
    np.testing.assert_array_equal(mirrored[::-1], prediction.log_mu[:local.size])
