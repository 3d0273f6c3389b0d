"""Exact vertical motion above the disc (the 1-D model of physics/vertical.py), by events.

Between events a granule's base height follows z + vz t - g t^2 / 2. Events: it reaches
the disc (impact: rebound e v, or rest once the rebound is below the settle speed) and
it crosses the vane-top level (vanes touch it only below). Steps are cut at events, so
every impact is taken at its exact time.
"""

from __future__ import annotations

import math

from spreadgym.physics.compiled.options import INLINED

NO_EVENT = 0
DISC_IMPACT = 1
VANE_TOP_CROSSING = 2


@INLINED
def time_to_disc(z, vz, g):
    """Time (s) until a flying granule at height z (m), vertical speed vz (m/s) lands."""
    return (vz + math.sqrt(vz * vz + 2.0 * g * z)) / g


@INLINED
def time_to_level(z, vz, level, g, below):
    """Time (s) until the base crosses `level` (upwards if `below`, else downwards); inf if never."""
    if below:
        disc = vz * vz - 2.0 * g * (level - z)
        if vz <= 0.0 or disc < 0.0:
            return math.inf
        return (vz - math.sqrt(disc)) / g
    return (vz + math.sqrt(vz * vz + 2.0 * g * max(z - level, 0.0))) / g


@INLINED
def next_event(z, vz, resting, below, level, g, horizon):
    """(time, kind) of the first vertical event within `horizon` s, else (horizon, NO_EVENT)."""
    t, kind = horizon, NO_EVENT
    if not resting:
        hit = time_to_disc(z, vz, g)
        if hit <= t:
            t, kind = hit, DISC_IMPACT
    cross = time_to_level(z, vz, level, g, below)
    if cross < t:
        t, kind = cross, VANE_TOP_CROSSING
    return t, kind


@INLINED
def advance(z, vz, resting, dt, g):
    """Height and vertical speed after dt s of free flight (unchanged at rest)."""
    if resting:
        return 0.0, 0.0
    return max(z + vz * dt - 0.5 * g * dt * dt, 0.0), vz - g * dt


@INLINED
def disc_impact(vz, restitution, settle_speed):
    """Impact on the disc at vertical speed vz < 0: (vz after, resting, normal impulse per mass)."""
    v_impact = -vz
    v_up = restitution * v_impact
    if v_up <= settle_speed:
        return 0.0, True, v_impact
    return v_up, False, (1.0 + restitution) * v_impact
