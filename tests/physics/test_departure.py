"""The departure summaries (compiled) against the same quantities written out in numpy."""

import numpy as np
import pytest

from spreadgym.physics.departure import DEPARTED, RETAINED_STUCK, Departure
from spreadgym.spread.pipeline import departure_summary


def departure(n: int, seed: int, retained: float) -> Departure:
    rng = np.random.default_rng(seed)
    angle = rng.uniform(-np.pi, np.pi, n)
    position = 0.15 * np.column_stack([np.cos(angle), np.sin(angle)])
    outcome = np.where(rng.random(n) < retained, RETAINED_STUCK, DEPARTED).astype(np.int8)
    return Departure(position_m=position, velocity_m_s=rng.normal(0.0, 8.0, (n, 2)), spin_rad_s=rng.normal(0, 50, n),
                     height_m=np.zeros(n), vertical_velocity_m_s=np.zeros(n), time_s=rng.uniform(0.05, 0.2, n),
                     outcome=outcome, model="test", dt_s=0.0)


@pytest.mark.parametrize("omega", [62.8, -62.8])
def test_summary_matches_numpy(omega):
    d = departure(5000, 1, 0.1)
    gone = d.outcome == DEPARTED
    pos, vel = d.position_m[gone], d.velocity_m_s[gone]
    unit = pos / np.hypot(pos[:, 0], pos[:, 1])[:, None]
    tangent = np.sign(omega) * np.column_stack([-unit[:, 1], unit[:, 0]])
    radial, tangential = np.sum(vel * unit, axis=1), np.sum(vel * tangent, axis=1)
    got_radial, got_tangential = d.radial_tangential_m_s(omega)
    np.testing.assert_array_equal(got_radial, radial)
    np.testing.assert_array_equal(got_tangential, tangential)
    speed = np.hypot(vel[:, 0], vel[:, 1])
    want = {"speed_mean_m_s": speed.mean(), "speed_std_m_s": speed.std(ddof=1),
            "spin_mean_rad_s": d.spin_rad_s[gone].mean(),
            "angle_mean_deg": np.degrees(np.arctan2(radial, tangential)).mean(),
            "time_on_spinner_mean_s": d.time_s[gone].mean()}
    got = departure_summary(d, omega)
    assert got.keys() == want.keys()
    for key, value in want.items():
        assert got[key] == pytest.approx(value, rel=1e-12, abs=1e-12), key


def test_one_or_no_granule_departed():
    one = departure(3, 2, 0.0)
    one.outcome[1:] = RETAINED_STUCK
    assert departure_summary(one, 10.0)["speed_std_m_s"] == 0.0
    one.outcome[:] = RETAINED_STUCK
    assert set(departure_summary(one, 10.0).values()) == {None}
