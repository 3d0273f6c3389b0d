"""The tray file: what it accepts and the one-line errors (with line numbers) for what it does not."""

import numpy as np
import pytest

from spreadgym.config.scene import load_scene
from spreadgym.errors import ConfigError, SpreadgymError
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
    ("x_m,grams\n0,1\n", "line 1: unknown column 'grams'"),
    ("x_m,mass\n0,1\n", "line 1: column 'mass' has no unit; write mass_g"),
    ("x_m,mass_lb\n0,1\n", "line 1: column 'mass_lb': unknown unit 'lb'"),
    ("x_m\n0\n", "line 1: missing column mass"),
    ("x_m,mass_g,mass_kg\n0,1,1\n", "line 1: column mass is named twice"),
    ("# only\n", "no header line"),
    ("x_m,mass_g\n0,1\n0.5,-2\n1,1\n1.5,1\n2,1\n", "line 3: mass_g -2 is negative"),
    ("x_m,mass_g\n0,1\n0.5,nan\n1,1\n1.5,1\n2,1\n", "line 3: mass_g 'nan' is not finite"),
    ("x_m,mass_g\n0,1\n0.5,inf\n1,1\n1.5,1\n2,1\n", "line 3: mass_g 'inf' is not finite"),
    ("x_m,mass_g\n0,1\n0.5,abc\n", "line 3: mass_g 'abc' is not a number"),
    ("x_m,mass_g\n0,1\n0.5,1e-320\n", "line 3: mass_g 1e-320 is out of range; allowed: 0 (an empty tray) or 1e-06"),
    ("x_m,mass_g\n0,1\n1000000,1\n", "line 3: x_m 1000000 is 1e+06 m from the machine; allowed: within 200 m"),
    ("x_m,mass_g\n0,1\n0.3,1\n1,1\n1.5,1\n2,1\n", "line 3: trays at x = 0 and 0.3 m of pass 0 overlap"),
    ("x_m,mass_g\n0,1\n0.5,1\n0.5,2\n1.5,1\n2,1\n", "line 4: tray x = 0.5 m of pass 0 is given twice (also line 3)"),
    ("x_m,mass_g\n0,1\n0.5,1\n1,1\n1.5,1\n", "line 5: 4 trays; allowed: at least 5"),
    ("x_m,mass_g\n0,1\n0.5,1\n1,0\n1.5,0\n2,0\n", "line 6: 2 trays caught anything; at least 5 must"),
    ("x_m,mass_g\n0,1,3\n", "line 2: 3 values for 2 columns"),
    ("x_m,mass_g,pass\n0,1,a\n", "line 2: pass 'a' is not a whole number"),
    ("x_m,mass_g\n0,1\n0.5,1_0\n", "line 3: mass_g '1_0' is not a number"),  # float() reads it as 10
    ("x_m,mass_g,pass\n0,1,1_0\n", "line 2: pass '1_0' is not a whole number"),
    ("x_m,mass_g\n0," + "1" * 200_000 + "\n", "line 2: longer than 10000 characters"),
    ("x_m,mass_g\n0,\"1\n", "line 2: "),
    ("x_m,mass_g\n0,1\0\n", "line 2: holds a NUL character"),
    ("x_m,mass_g\n" + "".join(f"{0.5 * i},1\n" for i in range(4001)), "more than 4000 trays"),
])
def test_bad_files_give_one_line_with_the_line_number(text, expected):
    with pytest.raises(SpreadgymError) as info:
        parse_trays(text, 0.5)
    message = str(info.value)
    assert expected in message and "\n" not in message


def test_spaced_trays_on_any_layout_are_read_as_they_lie():
    """0.5 m trays every 1 m (a field kit), and an irregular kit: no grid, the gaps kept."""
    spaced = parse_trays("x_m,mass_g\n" + "".join(f"{x},{1 + abs(x)}\n" for x in range(-6, 7)), 0.5)
    np.testing.assert_allclose(spaced.x_m, np.arange(-6, 7))
    irregular = parse_trays("x_m,mass_g\n-7.3,1\n-2.15,4\n0.4,6\n3.05,3\n8.9,1\n", 0.5)
    np.testing.assert_allclose(irregular.x_m, [-7.3, -2.15, 0.4, 3.05, 8.9])


@pytest.mark.parametrize("text", [
    "x_m;mass_g\n-1,0;2,5\n-0,5;3\n0;4\n0,5;3,5\n1,0;1,5\n1,5;0\n",  # a continental spreadsheet export
    "x [m];mass (g)\n-1;2.5\n-0.5;3\n0;4\n0.5;3.5\n1;1.5\n1.5;0\n",  # units in brackets
    "x_cm\tmass_kg\n-100\t0,0025\n-50\t0,003\n0\t0,004\n50\t0,0035\n100\t0,0015\n150\t0\n",  # tabs
    "\"x (m)\",\"mass [mg]\"\n-1,2500\n-0.5,3000\n0,4000\n0.5,3500\n1,1500\n1.5,0\n",  # quoted, mg
])
def test_separators_decimal_commas_and_units(text):
    test = parse_trays(text, 0.5)
    np.testing.assert_allclose(test.x_m, [-1.0, -0.5, 0.0, 0.5, 1.0, 1.5])
    np.testing.assert_allclose(test.mass_kg, [2.5e-3, 3e-3, 4e-3, 3.5e-3, 1.5e-3, 0.0])


def test_a_pipe_a_device_and_a_folder_are_refused_at_once(tmp_path):
    import os

    pipe = tmp_path / "pipe"
    os.mkfifo(pipe)  # nothing writes it: reading would block forever
    for path in (pipe, "/dev/zero", tmp_path):
        with pytest.raises(SpreadgymError, match="is not a regular file"):
            read_trays(path, 0.5)


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
    pass0 = model.local_x_m[:local.size]
    assert model.local_x_m[local.size:2 * local.size].tolist() == (-pass0).tolist()
    assert model.local_x_m[2 * local.size:].tolist() == pass0.tolist()
    prediction = model.predict([[0.5]])[0]
    mirrored = prediction.log_mu[local.size:2 * local.size]
    np.testing.assert_array_equal(mirrored[::-1], prediction.log_mu[:local.size])


def test_soft_tray_masses_on_any_layout_equal_the_exact_overlaps():
    """Each landing spread evenly over SOFT_WIDTH w: a tray's catch is the overlap of every
    spread with the tray, summed (brute force, landing by landing), on a layout with gaps,
    an irregular one, trays of several passes overlapping, and trays 150 m away."""
    from spreadgym.fit.likelihood import SOFT_WIDTH, soft_tray_masses

    rng = np.random.default_rng(7)
    x = rng.normal(0.0, 3.0, 4000)
    mass = rng.uniform(1e-5, 3e-5, 4000)
    replicate = rng.integers(0, 4, 4000)
    w, h = 0.5, SOFT_WIDTH * 0.5
    for centres in (np.arange(-8, 9) * 1.0, np.array([-7.3, -2.15, 0.4, 0.55, 3.05, 8.9, 150.0])):
        got = soft_tray_masses(x, mass, replicate, 4, centres, w)
        overlap = (np.minimum(x[:, None] + h / 2, centres + w / 2) - np.maximum(x[:, None] - h / 2, centres - w / 2))
        share = np.clip(overlap, 0.0, None) / h
        exact = np.array([(mass[:, None] * share)[replicate == k].sum(axis=0) for k in range(4)])
        np.testing.assert_allclose(got, exact, rtol=1e-9, atol=1e-15)
    contiguous = soft_tray_masses(x, mass, replicate, 4, np.arange(-30, 31) * w, w)
    assert contiguous.sum() == pytest.approx(mass.sum(), rel=1e-12)  # touching trays catch every landing


def test_a_byte_order_mark_is_read_as_the_file_reader_reads_it(tmp_path):
    """Spreadsheets' "CSV UTF-8" starts with a byte-order mark: the page's text and the CLI's file read alike."""
    text = "x_m,mass_g\n" + "".join(f"{0.5 * i},{1.0 + 0.1 * i}\n" for i in range(-3, 4))
    path = tmp_path / "trays.csv"
    path.write_text("\ufeff" + text, encoding="utf-8")
    from_file = read_trays(path, 0.5)
    from_text = parse_trays("\ufeff" + text, 0.5)
    assert np.array_equal(from_text.x_m, from_file.x_m) and np.array_equal(from_text.mass_kg, from_file.mass_kg)


def test_a_fit_key_of_a_section_the_scene_lacks_is_refused():
    """Fitting twin.spacing_m on a one-disc scene would have made it a twin-disc machine."""
    with pytest.raises(ConfigError, match="twin.spacing_m: this scene has no twin section"):
        parse_fit_specs(["twin.spacing_m=0.5:1"], load_scene("paper"))
    assert parse_fit_specs(["twin.spacing_m=0.7:1"], load_scene("twin-field")).keys == ("twin.spacing_m",)
