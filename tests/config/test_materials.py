"""The material library and `spreadgym materials`."""

from __future__ import annotations

import json

import pytest

from spreadgym.cli.main import main
from spreadgym.config.materials import PAIR_QUANTITIES, load_library
from spreadgym.errors import MaterialError

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
    assert set(lib.fertilizers) == {"mixture-17-21-17", "compound-10-16-10", "pellet"}
    assert set(lib.surfaces) == {"pvc", "steel", "aluminum", "rubber", "mc"}
    compound = lib.fertilizer("compound-10-16-10")
    assert compound.particle_density_kg_m3 == 1734.0  # Table 1, 1.734 g/cm3
    assert compound.pair("friction", "mc") == 0.52  # Table 2
    assert compound.pair("restitution", "steel") == 0.351  # Table 3
    assert compound.pair("impact_time_s", "pvc") == pytest.approx(2.581e-4)


def test_every_fertilizer_covers_every_surface():
    lib = load_library()
    for fert in lib.fertilizers.values():
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
    with pytest.raises(MaterialError, match="unknown fertilizer 'urea'"):
        lib.fertilizer("urea")
    with pytest.raises(MaterialError, match="unknown surface material 'glass'"):
        lib.check_surface("glass")


def test_materials_json(capsys):
    assert main(["materials", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) == {"fertilizers"}
    lib = load_library()
    assert set(data["fertilizers"]) == set(lib.fertilizers)
    for name, entry in data["fertilizers"].items():
        assert FERTILIZER_KEYS <= set(entry)
        fert = lib.fertilizer(name)
        assert entry["particle_density_kg_m3"] == fert.particle_density_kg_m3
        for quantity in ("friction", "restitution", "impact_time_s"):
            assert set(entry[quantity]) == set(lib.surfaces)
            assert entry[quantity] == dict(getattr(fert, quantity))
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
