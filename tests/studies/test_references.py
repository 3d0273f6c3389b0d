"""Converged references: stored one file per scene, reused only when they match, resumable."""

import json

from spreadgym.studies.references import compute_references, load_references, reference_family

TINY = {"sim.granules": 64}


def test_the_family_holds_the_documented_scenes():
    family = reference_family()
    assert {"paper", "paper-deflectors", "field", "field-locked"} <= set(family)
    assert family["paper-rpm300"].spinner.rpm == 300


def test_a_stored_reference_is_reused_when_it_matches_and_recomputed_when_it_does_not(tmp_path):
    said = []
    first = compute_references(tmp_path, model="analytic", runs=2, names=["paper"], overrides=TINY,
                               progress=said.append)
    assert said == ["paper: 2 runs, analytic"] and first[0]["granules"] == 128
    again = compute_references(tmp_path, model="analytic", names=["paper"], overrides=TINY, progress=said.append)
    assert len(said) == 1 and again == first  # runs not given: whatever was stored serves
    compute_references(tmp_path, model="analytic", runs=3, names=["paper"], overrides=TINY, progress=said.append)
    assert said[-1] == "paper: 3 runs, analytic"
    compute_references(tmp_path, model="analytic", runs=3, names=["paper"], overrides={"sim.granules": 32},
                       progress=said.append)
    assert len(said) == 3  # other overrides: recomputed
    stored = load_references(tmp_path, "analytic")["paper"]
    assert stored["settings"] == {"model": "analytic", "runs": 3, "overrides": {"sim.granules": 32}}
    assert not list(tmp_path.rglob("*.partial")) and (tmp_path / "analytic.md").is_file()
    assert json.loads((tmp_path / "analytic" / "paper.json").read_text())["granules"] == 96


def test_the_table_lists_every_stored_scene_when_one_is_added(tmp_path):
    compute_references(tmp_path, model="analytic", runs=2, names=["paper"], overrides=TINY)
    compute_references(tmp_path, model="analytic", runs=2, names=["field"], overrides=TINY)
    rows = [line.split("|")[1].strip() for line in (tmp_path / "analytic.md").read_text().splitlines()[4:]]
    assert rows == ["paper", "field"]  # family order, the earlier scene kept
