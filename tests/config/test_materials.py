"""The material library and `spreadgym materials`."""

from __future__ import annotations

import json
import os
import re

import pytest

from spreadgym.cli.main import main
from spreadgym.config.materials import PAIR_QUANTITIES, load_library
from spreadgym.errors import ConfigError, MaterialError

FERTILIZER_KEYS = {
    "particle_density_kg_m3",
    "bulk_density_kg_m3",
    "repose_angle_deg",
    "friction",
    "restitution",
    "impact_time_s",
}


def test_library_holds_the_paper_tables():
    lib = load_library()
    assert {"mixture-17-21-17", "compound-10-16-10", "pellet"} <= set(lib.fertilizers)
    assert set(lib.surfaces) == {"pvc", "steel", "aluminum", "rubber", "mc"}
    compound = lib.fertilizer("compound-10-16-10")
    assert compound.particle_density_kg_m3 == 1734.0  # Table 1, 1.734 g/cm3
    assert compound.pair("friction", "mc") == 0.52  # Table 2
    assert compound.pair("restitution", "steel") == 0.351  # Table 3
    assert compound.pair("impact_time_s", "pvc") == pytest.approx(2.581e-4)


def test_every_seed_fertilizer_covers_every_surface():
    lib = load_library()
    for fert in (lib.fertilizer(name) for name in ("mixture-17-21-17", "compound-10-16-10", "pellet")):
        for quantity in PAIR_QUANTITIES:
            assert set(getattr(fert, quantity)) == set(lib.surfaces), (fert.name, quantity)
        for surface, e in fert.restitution.items():
            t = fert.impact_time_s[surface]
            assert (e is None) == (t is None), (fert.name, surface)
            if e is not None:
                assert 0 < e <= 1 and 0 < t < 1e-3  # within one 1 ms frame interval
        for surface in fert.paper_stiffness_n_per_m:
            assert fert.restitution[surface] is not None
            assert surface in fert.paper_damping_ns_per_m


def test_unmeasured_pair_names_the_pair():
    lib = load_library()
    with pytest.raises(MaterialError, match="pellet/rubber"):
        lib.fertilizer("pellet").pair("restitution", "rubber")
    with pytest.raises(MaterialError, match="unknown fertilizer 'guano'"):
        lib.fertilizer("guano")
    with pytest.raises(MaterialError, match="unknown surface material 'glass'"):
        lib.check_surface("glass")


def test_materials_json(capsys):
    assert main(["materials", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) == {"fertilizers", "sources"}
    lib = load_library()
    assert set(data["fertilizers"]) == set(lib.fertilizers)
    for name, entry in data["fertilizers"].items():
        assert FERTILIZER_KEYS <= set(entry)
        fert = lib.fertilizer(name)
        assert entry["particle_density_kg_m3"] == fert.particle_density_kg_m3
        for quantity in PAIR_QUANTITIES:
            assert entry[quantity] == dict(getattr(fert, quantity))
        assert (entry["cannot_run"] is None) == bool(entry["runs_on"])
    assert data["fertilizers"]["mixture-17-21-17"]["runs_on"] == []
    assert "restitution" in data["fertilizers"]["mixture-17-21-17"]["cannot_run"]
    assert data["fertilizers"]["potassium-chloride"]["runs_on"] == ["steel", "mc"]
    pellet = data["fertilizers"]["pellet"]
    assert pellet["restitution"]["steel"] == 0.525
    assert pellet["restitution"]["rubber"] is None
    assert pellet["impact_time_s"]["aluminum"] is None
    assert data["fertilizers"]["mixture-17-21-17"]["friction"]["rubber"] == 1.23


def test_materials_tables(capsys):
    assert main(["materials"]) == 0
    out = capsys.readouterr().out
    for word in ("compound-10-16-10", "pellet", "steel", "0.351", "0.0002581", "1734"):
        assert word in out
    assert "{" not in out


# --- provenance, the new fertilizers, user files and inline fertilizers -------------------------

COMMON_FERTILIZERS = ("urea", "ammonium-nitrate", "calcium-ammonium-nitrate", "potassium-chloride",
                      "diammonium-phosphate", "triple-superphosphate")


def numbers_of(entry, prefix=""):
    """(dotted key, value) of every number in a raw library entry (provenance itself aside)."""
    for key, value in entry.items():
        if key in ("provenance", "description", "name"):
            continue
        dotted = f"{prefix}{key}"
        if isinstance(value, dict):
            yield from numbers_of(value, dotted + ".")
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            yield dotted, value


def test_every_number_of_the_library_names_its_source():
    """A number without a provenance entry (its key or a key above it) naming a known source fails."""
    from spreadgym.config.resources import config_dir, read_yaml

    raw = read_yaml(config_dir() / "materials.yaml")
    sources = set(raw["sources"])
    for name, entry in raw["fertilizers"].items():
        provenance = entry.get("provenance", {})
        for key, _ in numbers_of(entry):
            parts = key.split(".")
            covering = [".".join(parts[:i]) for i in range(len(parts), 0, -1) if ".".join(parts[:i]) in provenance]
            assert covering, f"{name}.{key} has no provenance"
            source = provenance[covering[0]].split(":", 1)[0]
            assert source in sources, f"{name}.{key}: unknown source {source!r}"


def test_the_common_fertilizers_are_in_the_library_with_explicit_nulls():
    lib = load_library()
    for name in COMMON_FERTILIZERS:
        assert name in lib.fertilizers
    with pytest.raises(MaterialError, match="urea/steel was not measured"):
        lib.fertilizer("urea").pair("friction", "steel")
    with pytest.raises(MaterialError, match="particle_density_kg_m3 and size of diammonium-phosphate not measured"):
        lib.fertilizer("diammonium-phosphate").granule_properties()
    kcl = lib.fertilizer("potassium-chloride")
    assert kcl.pair("rolling_resistance", "steel") > 0 and kcl.pair("friction", "mc") == 0.44


def test_a_user_materials_file_merges_over_the_library(tmp_path):
    user = tmp_path / "mine.yaml"
    user.write_text("fertilizers:\n"
                    "  urea:\n"
                    "    friction: {steel: 0.4, mc: 0.41}\n"
                    "    restitution: {steel: 0.3, mc: 0.32}\n"
                    "    rolling_resistance: {steel: 0.05, mc: 0.05}\n"
                    "  my-blend:\n"
                    "    particle_density_kg_m3: 1600\n"
                    "    friction: {mc: 0.5}\n"
                    "    restitution: {mc: 0.4}\n"
                    "    size: {d50_m: 0.0032, sd_m: 0.0004, min_m: 0.002, max_m: 0.005}\n")
    lib = load_library(extra=user)
    urea = lib.fertilizer("urea")
    assert urea.particle_density_kg_m3 == 1325.0  # kept from the library
    assert urea.pair("friction", "mc") == 0.41 and urea.pair("rolling_resistance", "steel") == 0.05
    blend = lib.fertilizer("my-blend")
    assert blend.pair("rolling_resistance", "mc") == 0.0  # left out: the loss-free roller
    assert "compound-10-16-10" in lib.fertilizers


@pytest.mark.parametrize("entry,message", [
    ("    colour: red\n", "fertilizers.bad.colour: unknown key"),
    ("    particle_density_kg_m3: -5\n", "fertilizers.bad.particle_density_kg_m3: Input should be greater than 0"),
    ("    size: {d50_m: 0.003, sd_m: 0.001, min_m: 0.004, max_m: 0.005}\n", "sizes out of order"),
    ("    restitution: {mc: 1.5}\n", "fertilizers.bad.restitution.mc: 1.5 outside [0, 1]"),
    ("    restitution: {mc: 0.4, mcc: 0.2}\n", "fertilizers.bad.restitution.mcc: unknown surface"),
])
def test_a_bad_user_fertilizer_is_one_line_naming_the_key(tmp_path, entry, message):
    base = {"particle_density_kg_m3": "    particle_density_kg_m3: 1500\n",
            "friction": "    friction: {mc: 0.5}\n", "restitution": "    restitution: {mc: 0.4}\n",
            "size": "    size: {d50_m: 0.003, sd_m: 0.001, min_m: 0.002, max_m: 0.005}\n"}
    key = entry.strip().split(":")[0]
    base[key] = entry
    user = tmp_path / "bad.yaml"
    user.write_text("fertilizers:\n  bad:\n" + "".join(base.values()))
    with pytest.raises(ConfigError, match=re.escape(message)) as info:
        load_library(extra=user)
    assert "\n" not in str(info.value)


def test_a_missing_pair_of_a_new_user_fertilizer_is_named(tmp_path):
    user = tmp_path / "partial.yaml"
    user.write_text("fertilizers:\n  partial:\n    particle_density_kg_m3: 1500\n    friction: {mc: 0.5}\n"
                    "    size: {d50_m: 0.003, sd_m: 0.001, min_m: 0.002, max_m: 0.005}\n")
    with pytest.raises(ConfigError, match="fertilizers.partial.restitution: missing"):
        load_library(extra=user)


def test_spreadgym_materials_is_the_default_users_file(copied_fertilizer, monkeypatch):
    """SPREADGYM_MATERIALS (what serve --materials and chart --materials set for their workers) is merged over
    the shipped library wherever no other file is named; user_materials sets it for a block and puts it back."""
    from spreadgym.config.materials import MATERIALS_ENV, user_materials

    path, name = copied_fertilizer
    monkeypatch.delenv(MATERIALS_ENV, raising=False)
    assert name not in load_library().fertilizers
    with user_materials(path):
        copy, original = load_library().fertilizer(name), load_library().fertilizer("compound-10-16-10")
        assert copy.particle_density_kg_m3 == original.particle_density_kg_m3
        assert copy.pair("friction", "mc") == original.pair("friction", "mc")
    assert MATERIALS_ENV not in os.environ and name not in load_library().fertilizers
    monkeypatch.setenv(MATERIALS_ENV, str(path.parent / "missing.yaml"))
    with pytest.raises(ConfigError, match="SPREADGYM_MATERIALS: .*missing.yaml: file not found"):
        load_library()


def test_a_new_surface_comes_with_its_friction(tmp_path):
    user = tmp_path / "own.yaml"
    user.write_text("fertilizers:\n  pellet:\n    friction: {glass: 0.3}\n    restitution: {glass: 0.5}\n")
    assert load_library(extra=user).fertilizer("pellet").pair("restitution", "glass") == 0.5
