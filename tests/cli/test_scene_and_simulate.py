"""Scene validation, --set overrides, and the `simulate` command's contract."""

import json
import subprocess
import sys

import numpy as np
import pytest

from spreadgym.cli.main import main
from spreadgym.config.overrides import parse_assignments
from spreadgym.config.scene import load_scene
from spreadgym.errors import ConfigError, MaterialError
from spreadgym.physics.contacts import resolve_contacts
from spreadgym.physics.numerics import choose_time_step


@pytest.mark.parametrize(
    "overrides, key, fragment",
    [
        ({"vanes.outer_radius_m": 0.2}, "vanes.outer_radius_m", "longer than the disc radius 0.15"),
        ({"vanes.thickness_m": 0.0}, "vanes.thickness_m", "greater than 0"),
        ({"vanes.thickness_m": -0.001}, "vanes.thickness_m", "greater than 0"),
        ({"spinner.rpm": 0}, "spinner.rpm", "allowed: >= 10, <= 5000"),
        ({"spinner.rpm": -500}, "spinner.rpm", "allowed: >= 10, <= 5000"),
        ({"spinner.direction": "up"}, "spinner.direction", "'ccw' or 'cw'"),
        ({"vanes.pitch_deg": 75.0}, "vanes", "outside [-60.0, 60.0]"),
        ({"feed.radius_m": 0.2}, "feed.radius_m", "inside the disc radius"),
        ({"pattern.target_swath_m": 3.2}, "pattern", "not a positive multiple of tray_width_m"),
        ({"pattern.tray_width_m": 0.0}, "pattern.tray_width_m", "allowed: >= 0.05, <= 5"),
        ({"pattern.driving": "spiral"}, "pattern.driving", "'racetrack' or 'back-and-forth'"),
        ({"spinner.height_m": -0.1}, "spinner.height_m", "greater than or equal to 0"),
        ({"granule.rotation": "wobbly"}, "granule.rotation", "'free' or 'locked'"),
    ],
)
def test_bad_scene_values_name_the_key_and_the_limit(overrides, key, fragment):
    with pytest.raises(ConfigError) as err:
        load_scene("paper", overrides)
    assert err.value.key.startswith(key) and fragment in str(err.value)


def test_unknown_key_is_named():
    with pytest.raises(ConfigError, match="spinner.rmp: unknown key"):
        load_scene("paper", {"spinner.rmp": 500})


def test_unknown_materials_and_fertilizers_are_named(library):
    with pytest.raises(MaterialError, match="'wood'"):
        resolve_contacts(load_scene("paper", {"spinner.material": "wood"}), library)
    with pytest.raises(MaterialError, match="unknown fertilizer 'guano'"):
        resolve_contacts(load_scene("paper", {"fertilizer": "guano"}), library)
    with pytest.raises(MaterialError, match="mixture-17-21-17/mc"):
        resolve_contacts(load_scene("paper", {"fertilizer": "mixture-17-21-17"}), library)
    # ... unless the scene supplies the missing pair values
    resolve_contacts(load_scene("paper", {"fertilizer": "mixture-17-21-17", "contact.vane_restitution": 0.4,
                                          "contact.disc_restitution": 0.4}), library)


def test_hand_set_step_beyond_the_tunnelling_limit_is_refused():
    scene = load_scene("paper", {"sim.dt_s": 1e-3})
    with pytest.raises(ConfigError, match="sim.dt_s: .* no-tunnelling limit of this scene is 0.000414"):
        choose_time_step(scene, 0.00075)
    assert choose_time_step(load_scene("paper", {"sim.dt_s": 2e-4}), 0.00075).dt_s == 2e-4


def test_set_values_are_yaml():
    assert parse_assignments(["deflectors=[]", "spinner.rpm=800", "vanes.pitch_deg=[0, 5, 10, 15]"]) == {
        "deflectors": [], "spinner.rpm": 800, "vanes.pitch_deg": [0, 5, 10, 15]}
    scene = load_scene("paper-deflectors", parse_assignments(["deflectors=[]", "sim.seed=3"]))
    assert scene.deflectors == [] and scene.sim.seed == 3
    assert load_scene("paper-deflectors", {"deflectors.1.angle_deg": 100.0}).deflectors[1].angle_deg == 100.0


SIMULATE_KEYS = {"model", "dt_s", "granules", "departure", "wall_s", "target_swath_m", "driving", "tray_width_m",
                 "cv_percent_at_target", "cv_standard_error_percent", "cv_raw_percent", "cv_ci_percent",
                 "effective_swath_m", "trays", "mass"}
DEPARTURE_KEYS = {"speed_mean_m_s", "speed_std_m_s", "spin_mean_rad_s", "angle_mean_deg", "time_on_spinner_mean_s"}


def test_simulate_json_contract_and_mass_balance(capsys):
    assert main(["simulate", "--set", "sim.granules=150", "--model", "pymunk", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert SIMULATE_KEYS <= set(out) and DEPARTURE_KEYS == set(out["departure"])
    assert out["model"] == "pymunk" and out["granules"] == 150
    mass = out["mass"]
    assert mass["released_kg"] == pytest.approx(mass["landed_kg"] + mass["retained_kg"], rel=1e-12)
    trays = np.array(out["trays"]["mass_kg"])
    assert trays.sum() == pytest.approx(mass["landed_kg"], rel=1e-12)
    # outside checks recompute the plain tray CV from the trays: it must match the reported one
    centers = np.array(out["trays"]["center_m"])
    n = round(out["target_swath_m"] / out["tray_width_m"])
    k = np.round(centers / out["tray_width_m"]).astype(int)
    bout = np.bincount((k + n // 2) % n, weights=trays, minlength=n)  # racetrack fold
    assert 100 * bout.std(ddof=1) / bout.mean() == pytest.approx(out["cv_raw_percent"], rel=1e-9)
    # the reported CV is that one corrected for counting noise, inside its interval
    lo, hi = out["cv_ci_percent"]
    assert 0 <= lo <= out["cv_percent_at_target"] <= hi and out["cv_standard_error_percent"] > 0


def test_simulate_bad_input_exits_2_without_traceback():
    for args in (["--set", "spinner.rpm=-1"], ["--set", "sim.dt_s=0.01"], ["--scene", "nowhere"],
                 ["--set", "spinner.material=wood"], ["--set", "noequals"]):
        proc = subprocess.run([sys.executable, "-m", "spreadgym.cli.main", "simulate", *args],
                              capture_output=True, text=True)
        assert proc.returncode == 2, (args, proc.stderr)
        assert "Traceback" not in proc.stderr and "error" in proc.stderr
