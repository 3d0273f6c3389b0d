"""Each granule's regime on the vane (sliding or rolling), read alike from either model's
departures, and the identifiability rule that withholds a key whose interval spans a
change of regime."""

from spreadgym.config.scene import load_scene
from spreadgym.fit.regime import rolling, switched
from spreadgym.fit.run import fit_tray_test
from spreadgym.fit.space import parse_fit_specs
from spreadgym.fit.synthetic import synthetic_tray_test
from spreadgym.fit.uncertainty import IDENTIFIABLE_SHARE, REGIME_SWITCH, determined
from spreadgym.spread.pipeline import run_scene

FRICTION = "contact.vane_friction"


def _rolling(scene_name, rotation, friction, model="compiled", granules=2048):
    scene = load_scene(scene_name, {"granule.rotation": rotation, FRICTION: friction, "sim.granules": granules,
                                    "sim.seed": 7})
    return rolling(run_scene(scene, model=model, ci=False))


def test_locked_granules_slide_and_free_ones_roll_above_the_change():
    """Locked rotation: no granule rolls. Free: none at vane friction 0.2; above the change
    (about 0.3 on the field scene) most do, and the same granules at 0.4 and 0.6: friction
    above the change leaves a rolling granule as it is."""
    assert not _rolling("field", "locked", 0.5).any()
    assert _rolling("field", "free", 0.2).mean() < 0.01
    high, higher = _rolling("field", "free", 0.4), _rolling("field", "free", 0.6)
    assert high.mean() > 0.5
    assert switched(high, higher) == 0.0


def test_the_full_model_rolls_the_same_granules():
    """The same granules in both models: the full model's departures read as rolling for
    all but a few of those the compiled model rolls (fewer than REGIME_SWITCH)."""
    compiled, full = (_rolling("paper", "free", 0.45, model, 1024) for model in ("compiled", "pymunk"))
    assert full.mean() > 0.8
    assert switched(compiled, full) < REGIME_SWITCH


def test_each_disc_of_a_twin_machine_is_read_in_its_own_frame():
    """The second disc (mirrored, moved across the track) rolls the same granules as one disc alone."""
    one = _rolling("paper", "free", 0.45)
    twin = rolling(run_scene(load_scene("paper", {"twin": {"spacing_m": 0.8}, "granule.rotation": "free",
                                                  FRICTION: 0.45, "sim.granules": 2048, "sim.seed": 7}),
                             model="compiled", ci=False))
    assert one.mean() > 0.5
    assert (twin[:one.size] == one).all() and (twin[one.size:] == one).all()


def test_determined_needs_a_narrow_interval_and_no_change_of_regime():
    assert determined(0.2, 0.2 + IDENTIFIABLE_SHARE, 0.0)
    assert not determined(0.2, 0.21 + IDENTIFIABLE_SHARE, 0.0)
    assert determined(0.2, 0.3, REGIME_SWITCH)
    assert not determined(0.2, 0.3, 2 * REGIME_SWITCH)


def test_an_interval_across_the_change_of_regime_is_not_identifiable():
    """A test made by the compiled model itself at vane friction 0.26, inside its change
    from sliding to rolling: the interval is narrow and holds the truth, but granules
    change regime inside it, so the fit withholds the key (the full model changes regime
    at another friction: docs/fit.md)."""
    scene = load_scene("field")
    test = synthetic_tray_test(scene, {FRICTION: 0.26}, model="compiled", granules=16384, noise_seed=1)
    fit = fit_tray_test(scene, parse_fit_specs([f"{FRICTION}=0.2:0.8"], scene), test, granules=2048, seed=1)
    assert fit.low[0] <= 0.26 <= fit.high[0]
    assert fit.high[0] - fit.low[0] <= IDENTIFIABLE_SHARE * 0.6
    assert fit.regime_switch[0] > REGIME_SWITCH
    assert not fit.identifiable[FRICTION]


def test_a_search_box_past_the_compiled_models_envelope_is_said_before_the_fit():
    """A rolling resistance searched past 0.6 (the compiled model's validated envelope) sends `auto`'s
    evaluations there to the full model; the fit names the corner before it starts, and says nothing for a box
    inside the envelope or a model given by name."""
    from spreadgym.config.scene import load_scene
    from spreadgym.fit.space import full_model_corner, parse_fit_specs
    from spreadgym.physics.selection import VALIDATED

    scene = load_scene("paper", {"granule.rotation": "free"})
    inside = parse_fit_specs([f"contact.rolling_resistance=0:{VALIDATED['rolling_resistance'][1]}"], scene)
    past = parse_fit_specs(["contact.vane_friction=0.2:0.8,contact.rolling_resistance=0:0.8"], scene)
    assert full_model_corner(inside, scene) == ""
    said = full_model_corner(past, scene)
    assert "contact.rolling_resistance=0.8" in said and "full model runs" in said
    assert full_model_corner(past, scene, "compiled") == ""
