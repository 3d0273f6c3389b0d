"""Locating an event inside a step: the Illinois variant of regula falsi, one update."""

from __future__ import annotations

from spreadgym.physics.compiled.layout import KERNEL


@KERNEL
def illinois_step(lo, hi, g_lo, g_hi, f, g):
    """One update of the bracket [lo, hi] (fractions of the step) on the event value g
    found at f (g >= 0 before the event, < 0 past it); the end kept twice has its value
    halved. Returns (lo, hi, g_lo, g_hi, next f, converged): converged when the two end
    values are equal, and then f is kept."""
    if g < 0.0:
        hi, g_hi = f, g
        g_lo *= 0.5
    else:
        lo, g_lo = f, g
        g_hi *= 0.5
    if g_lo == g_hi:
        return lo, hi, g_lo, g_hi, f, True
    return lo, hi, g_lo, g_hi, lo + (hi - lo) * g_lo / (g_lo - g_hi), False
