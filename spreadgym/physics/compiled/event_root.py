"""Locating an event inside a step, one update at a time: safeguarded Newton where the
event value's rate is at hand (the free phase), the Illinois variant of regula falsi
where it is not (the contact phase)."""

from __future__ import annotations

from spreadgym.physics.compiled.options import KERNEL

MAX_ITERATIONS = 40  # guard only: the Illinois iteration converges superlinearly (order ~1.44)
FRACTION_TOLERANCE = 1e-10  # the event time to this fraction of the step (~1e-13 s)


@KERNEL
def illinois_step(lo, hi, g_lo, g_hi, f, g, moved):
    """One update of the bracket [lo, hi] (fractions of the step) on the event value g
    found at f (g >= 0 before the event, < 0 past it). `moved`: the end the previous
    update replaced (-1 lo, +1 hi, 0 none yet); when the same end is replaced again, the
    other end's value is halved (Illinois), which keeps the convergence superlinear.
    Returns (lo, hi, g_lo, g_hi, next f, converged, moved): converged when the next f
    moves by FRACTION_TOLERANCE at most, or the two end values are equal (then f is kept)."""
    if g < 0.0:
        hi, g_hi = f, g
        if moved == 1:
            g_lo *= 0.5
        moved = 1
    else:
        lo, g_lo = f, g
        if moved == -1:
            g_hi *= 0.5
        moved = -1
    if g_lo == g_hi:
        return lo, hi, g_lo, g_hi, f, True, moved
    f_next = lo + (hi - lo) * g_lo / (g_lo - g_hi)
    return lo, hi, g_lo, g_hi, f_next, abs(f_next - f) <= FRACTION_TOLERANCE, moved


@KERNEL
def newton_step(lo, hi, f, g, slope):
    """One safeguarded Newton update of the bracket [lo, hi] (fractions of the step) on
    the event value g found at f (g >= 0 before the event, < 0 past it), slope = dg/df
    there. A Newton point outside the bracket (a grazing approach: slope near 0) is
    replaced by the bracket's midpoint, so the bracket at least halves. Returns (lo, hi,
    next f, converged): converged when g = 0 or the next f moves by FRACTION_TOLERANCE
    at most. Converges quadratically from a close guess (the regula falsi guess, or a
    rebound's parabola): 2-4 updates."""
    if g < 0.0:
        hi = f
    else:
        lo = f
    if g == 0.0:
        return lo, hi, f, True
    f_next = f - g / slope
    if not lo <= f_next <= hi:  # also a NaN from slope = 0
        f_next = 0.5 * (lo + hi)
    return lo, hi, f_next, abs(f_next - f) <= FRACTION_TOLERANCE
