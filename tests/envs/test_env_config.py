"""The shipped environment configs fit the models they run on."""

import pytest

from spreadgym.envs.common.config import load_env_config


@pytest.mark.parametrize("name", ["spinner_design", "spreader_tuning"])
def test_the_shipped_action_ranges_stay_inside_the_envelope_auto_serves_with_compiled(name):
    """An agent never moves `auto` from compiled to pymunk (200x slower) mid-episode."""
    from spreadgym.physics.selection import VALIDATED

    settings = load_env_config(name).settings
    for key in ("rpm", "pitch_deg"):
        lo, hi = getattr(settings, key)
        assert VALIDATED[key][0] <= lo and hi <= VALIDATED[key][1], key
