"""Robust chart cells: the variability model and its scene keys, common random numbers,
the p90 verification rebuilt from a row, the steady-row tie rule, the printable chart and
cells from a trained policy."""

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from spreadgym.agents.chart import make_spec, run_chart
from spreadgym.agents.chart import variability as var
from spreadgym.agents.chart.search import Scorer, objective, search
from spreadgym.agents.chart.spec import cell_seed
from spreadgym.cli.main import main
from spreadgym.config.materials import load_library
from spreadgym.config.scene import load_scene, scene_with
from spreadgym.errors import SpreadgymError
from spreadgym.spread.pipeline import run_scene

FERTILIZER = "compound-10-16-10"
DRAWS = {"draws": 4, "verify_draws": 4}
SMALL = dict(budget=6, granules=64, search_model="analytic", verify_runs=2, variability=DRAWS)


def test_defaults_are_the_documented_ones_and_overrides_are_checked():
    v = var.check_variability(None)
    assert {k: v[k] for k in var.FACTORS + var.OFFSETS} == {
        "disc_friction": 0.15, "vane_friction": 0.15, "restitution": 0.10, "size_median": 0.10, "density": 0.05,
        "disc_speed": 0.02, "vane_pitch_deg": 1.0}
    assert (v["draws"], v["verify_draws"], v["verify_runs_per_draw"], v["quantile"]) == (16, 16, 1, 0.9)
    assert var.check_variability({"density": 0.0, "draws": 8})["draws"] == 8
    for bad, message in [({"humidity": 0.1}, "variability.humidity: unknown key"),
                         ({"density": 0.9}, r"variability.density: 0.9 is out of range; allowed \[0, 0.5\]"),
                         ({"draws": 1}, "variability.draws: 1 is out of range"),
                         ({"verify_runs_per_draw": 0}, r"verify_runs_per_draw: 0 is out of range; allowed an integer "
                                                       r"in \[1, 8\]"),
                         ({"quantile": 1.0}, "variability.quantile")]:
        with pytest.raises(SpreadgymError, match=message):
            var.check_variability(bad)


def test_a_draw_maps_onto_the_scene_keys_and_the_density_onto_its_own_fertilizer():
    library = load_library()
    scene = load_scene("paper", {"fertilizer": "pellet"})
    draw = var.Draw(3, {"disc_friction": 1.1, "vane_friction": 0.9, "restitution": 1.05, "size_median": 0.95,
                        "density": 1.04, "disc_speed": 1.02}, math.radians(-0.5), 77)
    lib = var.draw_library(library, "pellet", [draw])
    out = var.perturbed(scene, {"spinner.rpm": 600.0, "vanes.pitch_deg": 10.0}, draw, lib)
    pellet = library.fertilizer("pellet")
    assert out["fertilizer"] == "pellet~3" and out["sim.seed"] == 77
    assert out["spinner.rpm"] == pytest.approx(612.0) and out["vanes.pitch_deg"] == pytest.approx(9.5)
    assert out["contact.disc_friction"] == pytest.approx(1.1 * pellet.pair("friction", "mc"))
    assert out["contact.vane_friction"] == pytest.approx(0.9 * pellet.pair("friction", "mc"))
    assert out["contact.vane_restitution"] == pytest.approx(1.05 * pellet.pair("restitution", "mc"))
    assert out["granule.diameter_m"] == pytest.approx(0.95 * pellet.size.d50_m)
    assert lib.fertilizer("pellet~3").particle_density_kg_m3 == pytest.approx(1.04 * pellet.particle_density_kg_m3)
    assert scene_with(scene, out).spinner.rpm == pytest.approx(612.0)  # the overrides make a valid scene


def test_every_candidate_of_a_cell_meets_the_same_draws():
    spec = make_spec("paper", FERTILIZER, "3", **SMALL)[0]
    seq = cell_seed(spec.seed, spec.cells[0]).spawn(5)[0]
    a, b = Scorer(spec, spec.cells[0], seq), Scorer(spec, spec.cells[0], seq)
    assert a.search_draws == b.search_draws and len(a.search_draws) == 4
    assert a.round_draws(1) == b.round_draws(1) != a.round_draws(0)
    x = np.array([0.2, -0.1])
    assert a.score_many([x], a.search_draws) == a.score_many([x], a.search_draws)  # common random numbers
    assert a.simulations == 8
    y = np.array([-0.4, 0.3])
    assert a.score_many([x, y], a.search_draws) == a.score_many([x], a.search_draws) + a.score_many([y], a.search_draws)


def test_a_candidates_draws_run_on_the_model_auto_picks_for_it_as_dialled():
    spec = make_spec("paper", FERTILIZER, "3", **{**SMALL, "search_model": "auto"})[0]
    scorer = Scorer(spec, spec.cells[0], cell_seed(spec.seed, spec.cells[0]).spawn(5)[0])
    top = scorer.space.overrides(np.array([1.0, 1.0]))  # 1100 rpm, 30 deg: draws reach 1122 rpm and 31 deg
    assert scorer.model(top) == "compiled"


def test_the_p90_is_the_full_model_over_the_rows_settings_on_fresh_draws(tmp_path):
    spec = make_spec("paper", FERTILIZER, "3", **SMALL)[0]
    assert spec.verify_simulations == 2 + 4
    result = run_chart(spec, tmp_path / "c", engine="local", progress=False)
    row, cell = result.payload["rows"][0], spec.cells[0]
    detail = json.loads((tmp_path / "c" / "cells" / f"{cell.key}.json").read_text(encoding="utf-8"))["detail"]
    draws_seq = cell_seed(spec.seed, cell).spawn(5)[3].spawn(2)[0]
    draws = var.draws(spec.variability, 4, draws_seq)
    library = var.draw_library(load_library(), FERTILIZER, draws)
    scene = spec.cell_scene(cell)
    settings = {"spinner.rpm": row["rpm"], "vanes.pitch_deg": row["pitch_deg"]}
    cvs = [objective(run_scene(scene_with(scene, var.perturbed(scene, settings, d, library)), model="pymunk",
                               library=library, ci=False).metrics, 3.0)[1] for d in draws]
    assert detail["verification_p90"]["cv_draws_percent"] == cvs
    assert row["cv_p90_percent"] == float(np.quantile(cvs, 0.9))
    html = (tmp_path / "c" / "chart.html").read_text(encoding="utf-8")
    assert "@media print" in html and "http" not in html and "<script" not in html
    assert f'<td class="width">3</td><td>{row["rpm"]:.0f}</td><td>{row["pitch_deg"]:.1f}</td>' in html
    assert f"<td>{row['cv_p90_percent']:.1f}</td>" in html


def _fake_scorer(cost):
    """A scorer of cost(x) + round noise (common to every point of a round)."""
    spec = SimpleNamespace(budget=40, objective="robust", steady_tolerance_pp=0.0, tie_preference="nearest")
    noise = np.random.default_rng(0).normal(0.0, 0.5, 1000)
    calls = []

    def score_many(xs, draws=None, seeds=None):
        calls.extend([draws] * len(xs))
        r = draws if isinstance(draws, int) else 999
        return [(cost(np.asarray(x)) + noise[r], 1.0) for x in xs]

    space = SimpleNamespace(size=2, values=lambda x: {"rpm": 650.0 + 450.0 * float(x[0])})
    return SimpleNamespace(spec=spec, space=space, search_draws=999, score_many=score_many,
                           round_draws=lambda r: r, fresh_seed=lambda k: k)


def test_among_ties_the_setting_nearest_the_narrower_neighbour_wins():
    flat = _fake_scorer(lambda x: 5.0)  # every setting as good as another: a tie
    neighbour = np.array([0.3, 0.3])
    picked = search(flat, np.zeros(2), 0.3, neighbour, cma_seed=1)
    assert np.array_equal(picked["x"], neighbour) and picked["ties"] >= 2
    # the default preference (issue 45): among the same ties, the lowest disc speed (unit axis 0) first
    gentle = _fake_scorer(lambda x: 5.0)
    gentle.spec.tie_preference = "lowest-rpm"
    chosen = search(gentle, np.zeros(2), 0.3, neighbour, cma_seed=1)
    speeds = [p["unit_settings"][0] for p in chosen["tie_set"]["points"]]
    assert chosen["x"][0] == min(speeds) < neighbour[0] and chosen["ties"] == picked["ties"]
    steep = _fake_scorer(lambda x: 100.0 * float(np.sum((x + 0.5) ** 2)))  # the neighbour is far worse
    picked = search(steep, np.full(2, -0.5), 0.3, np.array([0.9, 0.9]), cma_seed=1)
    assert np.linalg.norm(picked["x"] + 0.5) < 0.3


@pytest.fixture(scope="module")
def tiny_policy(tmp_path_factory):
    """A SpinnerDesign PPO policy trained for 64 steps on the closed-form model (seconds)."""
    from spreadgym.agents.training import train

    out = tmp_path_factory.mktemp("policy")
    train("ppo", out, overrides={"n_envs": 1, "env_kwargs.granules": 32, "env_kwargs.model": "analytic",
                                 "n_steps": 32, "batch_size": 32, "n_epochs": 1}, timesteps=64, log=lambda *a: None)
    return out


def test_a_policy_fills_every_cell_without_a_search_and_the_search_starts_there(tiny_policy, tmp_path):
    from spreadgym.agents.chart.policy import propose

    spec = make_spec("paper", FERTILIZER, "3,4", method="policy", policy=str(tiny_policy), **SMALL)[0]
    result = run_chart(spec, tmp_path / "p", engine="local", progress=False)
    rows, cells = result.payload["rows"], result.payload["cells"]
    assert all(c["search_evaluations"] == 0 and c["method"] == "policy" for c in cells)
    assert all(r["simulations"] == 2 + 4 and r["cv_percent"] is not None for r in rows)  # verification only
    proposal = propose(spec, spec.cells[0], cell_seed(spec.seed, spec.cells[0]).spawn(5)[4])
    assert cells[0]["unit_settings"] == proposal.tolist()
    both = make_spec("paper", FERTILIZER, "3", method="policy+search", policy=str(tiny_policy), **SMALL)[0]
    searched = run_chart(both, tmp_path / "ps", engine="local", progress=False).payload["cells"][0]
    assert searched["method"] == "policy+search" and searched["search_evaluations"] > 0


@pytest.mark.parametrize("argv, message", [
    (["--policy", "x.zip"], "--policy: not used by --method cmaes"),
    (["--method", "policy", "--policy", "nowhere/model.zip"], "--policy nowhere/model.zip: no such file"),
    (["--objective", "median"], "--objective: invalid choice"),
])
def test_bad_method_objective_or_policy_is_one_line_exit_2(argv, message, tmp_path, capsys):
    out = tmp_path / "out"
    args = ["chart", "--scene", "paper", "--fertilizers", FERTILIZER, "--widths", "3", "--out", str(out)] + argv
    try:
        code = main(args)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and message in err[-1] and not out.exists()


def test_a_variability_file_is_read_and_checked(tmp_path, capsys):
    good = tmp_path / "v.yaml"
    good.write_text("variability:\n  density: 0.0\n  draws: 8\n", encoding="utf-8")
    spec = make_spec("paper", FERTILIZER, "3", variability=str(good), budget=2)[0]
    assert spec.variability["density"] == 0.0 and spec.draws == 8 and spec.variability["disc_friction"] == 0.15
    bad = tmp_path / "bad.yaml"
    bad.write_text("variability:\n  humidity: 0.2\n", encoding="utf-8")
    code = main(["chart", "--scene", "paper", "--fertilizers", FERTILIZER, "--widths", "3", "--variability",
                 str(bad), "--out", str(tmp_path / "o")])
    assert code == 2 and "variability.humidity: unknown key" in capsys.readouterr().err


def test_quality_counts_reversals_and_the_robust_targets():
    from spreadgym.agents.chart.quality import chart_quality, reversals

    assert reversals([1.0, 3.0, 2.0, 4.0]) == [(1, 1.0), (2, 1.0)] and reversals([1.0, 2.0, 2.0, 5.0]) == []
    rows = [{"fertilizer": "a", "width_m": w, "rpm": rpm, "pitch_deg": pitch, "cv_percent": cv, "cv_p90_percent": p90}
            for w, rpm, pitch, cv, p90 in [(3, 500, 10, 2.0, 2.5), (4, 600, 14, 4.0, 7.0), (5, 580, 9, 9.0, 16.0),
                                           (6, 700, 12, 20.0, 25.0), (7, 700, 12, 1.0, 2.9)]]
    quality = chart_quality({"rows": rows})
    # the target p90 <= max(1.5 x nominal, nominal + 2 pp): 4 m: 7 > max(6, 6); 5 m: 16 > max(13.5, 11); 7 m is in
    # (2.9 <= 1 + 2) though over 1.5 x 1
    assert quality["p90_within_target_share"] == 0.6
    assert quality["p90_over_cap"] == [("a", 5)]
    # rpm turns by 20 of 600 and of 580 (3.3 and 3.4 %); pitch by 4 deg at 4 m and 3 deg (not over) at 5 m
    assert quality["reversals"]["a"] == {"rpm": [], "pitch": [(4, 4.0)]}
    assert (quality["rpm_reversals"], quality["pitch_reversals"]) == (0, 1)


def test_pooled_runs_per_batch_are_one_run_of_their_granules():
    from spreadgym.agents.chart.search import verify_p90

    spec = make_spec("paper", FERTILIZER, "3", **{**SMALL, "variability": {**DRAWS, "verify_runs_per_draw": 3}})[0]
    cell = spec.cells[0]
    scene = spec.cell_scene(cell)
    p90 = verify_p90(spec, cell, scene, {"spinner.rpm": 700.0, "vanes.pitch_deg": 5.0}, np.random.SeedSequence(1))
    assert (p90["runs_per_draw"], p90["granules"], p90["draws"]) == (3, 3 * 64, 4)
    assert spec.verify_simulations == 2 + 4 * 3


def test_chart_png_names_its_axes_in_the_charts_words():
    """chart.png's setting axes read 'disc speed (rpm)', 'vane pitch (°)', 'feed radius (mm)' (they read the
    column names: pitch_deg, feed_radius_m)."""
    from spreadgym.agents.chart.outputs import chart_axes

    spec = make_spec("twin-field", "compound-10-16-10", "24", budget=2)[0]
    names = ("pitch_deg", "feed_radius_m", "feed_angle_deg")
    rows = [{"fertilizer": "compound-10-16-10", "width_m": 24.0, "driving": "back-and-forth", "rpm": 900.0,
             "pitch_deg": 20.0, "feed_radius_m": 0.11, "feed_angle_deg": 120.0, "cv_percent": 7.0,
             "cv_standard_error_percent": 0.2, "cv_p90_percent": 9.0, "cv_p90_standard_error_percent": 0.3,
             "effective_swath_m": 25.0, "cv_search_percent": 7.1, "simulations": 10, "wall_s": 1.0}]
    fig = chart_axes(spec, rows, 15.0)
    labels = [ax.get_ylabel() for ax in fig.axes if ax.get_visible()]
    assert labels[1:] == ["disc speed (rpm)", "vane pitch (°)", "feed radius (mm)", "feed angle (°)"]
    assert not any(n in " ".join(labels) for n in names)
    assert fig.axes[3].get_lines()[0].get_ydata()[0] == pytest.approx(110.0)  # millimetres, as labelled


def test_a_chart_made_before_the_print_page_gets_one(tmp_path):
    """chart.html made again from chart.json (rewrite_printable): a chart from before robust cells and tie sets
    (docs/charts/paper) prints without a p90 column, with its machine, fixed settings, date and version, and its
    reversals flagged unpriced."""
    import shutil

    from spreadgym.agents.chart.outputs import rewrite_printable

    ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]
    shutil.copytree(ROOT / "docs" / "charts" / "paper", tmp_path / "paper")
    (tmp_path / "paper" / "chart.html").unlink(missing_ok=True)
    page = rewrite_printable(tmp_path / "paper").read_text(encoding="utf-8")
    assert "p90 CV" not in page and "no p90" in page and "made before steady rows" in page
    for expected in ("<dt>machine</dt>", "<dt>fixed settings</dt><dd>drop radius 43 mm; drop angle 105.0°</dd>",
                     "<dt>made by</dt><dd>spreadgym 0."):
        assert expected in page, expected
    assert page.count('class="turn"') == 7 and "compound-10-16-10 4 m: disc speed 901 → 647 → 1091 rpm" in page
