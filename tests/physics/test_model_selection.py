"""`auto` picks the cheapest exact-enough model; analytic and pymunk agree where both serve."""

import pytest

from spreadgym.config.scene import load_scene
from spreadgym.errors import ConfigError
from spreadgym.physics.selection import choose_model
from spreadgym.spread.pipeline import run_scene


def test_auto_picks_compiled_inside_the_validated_envelope_and_pymunk_outside():
    assert choose_model(load_scene("paper"))[0] == "compiled"
    assert choose_model(load_scene("field"))[0] == "compiled"
    model, reason = choose_model(load_scene("paper", {"spinner.rpm": 1500}))
    assert model == "pymunk" and "rpm 1500 outside [200, 1100]" in reason
    model, reason = choose_model(load_scene("paper", {"feed.drop_height_m": 0.2}))
    assert model == "pymunk" and "drop_height_m 0.2 outside" in reason
    assert choose_model(load_scene("paper", {"fertilizer": "potassium-chloride"}))[0] == "compiled"  # mu_r 0.31
    assert choose_model(load_scene("paper", {"contact.rolling_resistance": 0.6}))[0] == "compiled"  # paper-roll060
    model, reason = choose_model(load_scene("paper", {"contact.rolling_resistance": 0.8}))
    assert model == "pymunk" and "rolling_resistance 0.8 outside [0, 0.6]" in reason
    model, reason = choose_model(load_scene("paper"), "pymunk")
    assert (model, reason) == ("pymunk", "requested")
    with pytest.raises(ConfigError, match="model: unknown model 'dem'"):
        choose_model(load_scene("paper"), "dem")


@pytest.mark.parametrize("overrides", [
    {"granule.rotation": "locked"},
    {"granule.rotation": "free", "contact.vane_restitution": 0.0},
    {"granule.rotation": "locked", "spinner.rpm": 900, "vanes.pitch_deg": -15.0},
    {"granule.rotation": "free", "spinner.rpm": 1100, "vanes.pitch_deg": 10.0},
    {"granule.rotation": "locked", "spinner.radius_m": 0.3, "spinner.rpm": 700},
])
def test_analytic_and_pymunk_agree_on_departure_speed_within_half_a_percent(overrides):
    scene = load_scene("paper", {"feed.drop_height_m": 0.0, "sim.granules": 150, **overrides})
    analytic = run_scene(scene, model="analytic", ci=False).metrics.departure
    pymunk = run_scene(scene, model="pymunk", ci=False).metrics.departure
    assert analytic["speed_mean_m_s"] == pytest.approx(pymunk["speed_mean_m_s"], rel=0.005)
    assert analytic["angle_mean_deg"] == pytest.approx(pymunk["angle_mean_deg"], abs=0.5)


def test_auto_takes_the_compiled_plates_where_plates_stand_apart_and_the_full_model_where_they_nearly_touch():
    model, reason = choose_model(load_scene("paper-deflectors"))
    assert model == "compiled" and "plates bounce granules event by event" in reason
    assert "plates" not in choose_model(load_scene("paper"))[1]
    touching = [{"x_m": 0.3, "y_m": 0.0, "angle_deg": 90.0, "length_m": 0.2, "material": "steel"},
                {"x_m": 0.315, "y_m": 0.0, "angle_deg": 90.0, "length_m": 0.2, "material": "steel"}]
    model, reason = choose_model(load_scene("paper", {"deflectors": touching}))
    assert model == "pymunk" and "deflectors 0 and 1 12 mm apart (under 20 mm" in reason
