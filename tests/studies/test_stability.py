"""Where the methods fail (past each limit) and that each guard holds (small, fast versions)."""

import csv
import math

import numpy as np
import pytest

from spreadgym.config.scene import load_scene
from spreadgym.errors import ConfigError
from spreadgym.physics.numerics import choose_time_step, tunnelling_limit_s
from spreadgym.studies import stability as st

# --- a. pymunk tunnelling ------------------------------------------------------------------


def test_pymunk_vane_passes_through_granules_past_the_tunnelling_limit():
    local_limit = st.tunnelling_limits([1100])["limit_at_radius_s"][0]
    assert st.pymunk_tunnelling_fraction(1100, 3e-3, granules=8) >= 0.5
    assert st.pymunk_tunnelling_fraction(1100, 2.5 * local_limit, granules=8) > 0.0


@pytest.mark.parametrize("rpm", [200, 700, 1200])
def test_pymunk_guard_limit_and_automatic_step_never_tunnel(rpm):
    scene = load_scene("paper", {"spinner.rpm": rpm})
    limit = tunnelling_limit_s(scene, 0.0015)
    assert st.pymunk_tunnelling_fraction(rpm, limit, granules=8) == 0.0
    assert st.pymunk_tunnelling_fraction(rpm, choose_time_step(scene, 0.0015).dt_s, granules=8) == 0.0


def test_pymunk_guard_refuses_a_hand_set_step_beyond_the_limit():
    scene = load_scene("paper", {"spinner.rpm": 1100, "sim.dt_s": 1e-3})
    with pytest.raises(ConfigError) as info:
        choose_time_step(scene, 0.0015)
    assert info.value.key == "sim.dt_s"
    assert f"{tunnelling_limit_s(scene, 0.0015):.3g}" in str(info.value)


# --- b. spring-damper blow-up -------------------------------------------------------------


def contact(label_start):
    return next(c for c in st.table3_contacts() if c.label.startswith(label_start))


def test_paper_step_blows_up_the_stiffest_table3_contact_with_a_pellet_mass():
    pellet = contact("pellet/steel 20 mg")
    assert pellet.mass_kg == pytest.approx(19.7e-6, rel=0.01)
    assert pellet.critical_s < st.PAPER_DT_S  # 1.48e-5 s: the paper's step is 3.4x beyond
    rebound = st.rebound_over_steps(pellet, [st.PAPER_DT_S], phases=8)
    assert rebound["min"][0] > 1.0  # every impact leaves faster than it came
    assert rebound["energy_gain"][0] > 10.0
    assert np.all(np.isfinite([rebound[k][0] for k in rebound]))


def test_guarded_step_gives_the_restitution_for_every_table3_contact():
    for c in st.table3_contacts():
        rebound = st.rebound_over_steps(c, [c.guarded_s], phases=8)
        assert rebound["mean"][0] == pytest.approx(c.restitution, rel=0.02), c.label
        assert rebound["energy_gain"][0] <= 1.0 + 1e-12


def test_implied_660_mg_mass_is_stable_at_the_paper_step_but_blows_up_past_its_own_limit():
    heavy = contact("pellet/steel 660 mg")
    assert heavy.mass_kg == pytest.approx(660e-6, rel=0.01)
    assert heavy.critical_s > st.PAPER_DT_S  # 8.5e-5 s
    at_paper, past = (st.rebound_over_steps(heavy, [dt], phases=8) for dt in (st.PAPER_DT_S, 1.2 * heavy.critical_s))
    # Stable, but 3.3 steps per contact: the rebound depends on the entry phase.
    assert at_paper["energy_gain"][0] <= 1.0 + 1e-12
    assert at_paper["max"][0] - at_paper["min"][0] > 0.1 * heavy.restitution
    assert past["mean"][0] > 1.0


# --- c. disc-friction chatter -------------------------------------------------------------


def test_unguarded_disc_friction_chatters_and_the_guard_sticks():
    bad, good = st.disc_friction_chatter(False), st.disc_friction_chatter(True)
    coulomb, drift = float(bad["coulomb_dv"]), float(good["drift"])
    tail = slice(50, None)  # the granule has caught up with the disc by step ~35
    slip = bad["slip_tangential"][tail]
    assert np.all(np.sign(slip[1:]) != np.sign(slip[:-1]))  # reverses every step
    amplitude = np.hypot(bad["slip_tangential"][tail], bad["slip_radial"][tail])
    assert 0.1 * coulomb < amplitude.mean() < coulomb
    # Guarded: no tangential slip left, only the one-step centripetal drift omega^2 r dt.
    assert np.all(np.abs(good["slip_tangential"][tail]) < 0.01 * drift)
    assert np.allclose(good["slip_radial"][tail], drift, rtol=0.01)
    assert drift < 0.2 * coulomb


# --- d. flight step error -----------------------------------------------------------------


def test_fixed_step_rk4_landing_error_grows_past_a_millimetre_and_adaptive_stays_small():
    errors = st.flight_step_errors([0.01, 0.2], speeds_m_s=(20.0, 40.0), elevations_deg=(0.0, 15.0))
    small, large = errors["rk4_error_m"]
    assert small < 1e-3 < large
    assert float(errors["adaptive_error_m"]) < 1e-4


# --- the map ---------------------------------------------------------------------------------


def test_quick_map_draws_a_png_and_writes_every_panel(tmp_path):
    png, table = tmp_path / "map.png", tmp_path / "stability.csv"
    data = st.plot_stability_map(png, table, quick=True)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with table.open() as handle:
        rows = list(csv.DictReader(handle))
    assert {row["panel"] for row in rows} == {"a", "b", "c", "d"}
    assert data.tunnel_fraction.shape == (2, 2)
    assert math.isfinite(st.first_failure(np.array([1.0, 2.0]), np.array([0.0, 1.0]), 0.5))
