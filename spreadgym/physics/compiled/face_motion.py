"""Contact phase: a granule pressed against a flat vane face, rolling or sliding along it.

The centre moves on the face line c = p + x u + reach nf (nf the face's outward
normal); the state is (x, x', s). Along the face the frame's forces and the disc's
drag give G = (omega^2 c).u - sgn(x') mu_d g (drag while resting on the disc); the
face holds the granule with N = -(omega^2 c - 2 omega z x v).nf >= 0 (per unit mass;
Coriolis presses it on the leading face). Vane friction f acts along u, and the vane's
rolling resistance is a torque mu_r r N against the spin relative to the vane,
w = s - omega (type A of Ai et al. 2011: constant magnitude, directed against w; it
holds w = 0 when it can):
  sliding:  f = -eps mu_v N, eps = sgn(slip);   x'' = G + f,
            s' = -(q f + rho mu_r N) / (kappa r), rho = sgn(w); rho = 0 ("held"): s' = 0
  no slip:  f = -(G + q rho mu_r N / kappa) / (1 + 1/kappa) (rolling of a free sphere;
            rho = q sgn(x'); for locked rotation the contact point is held, f = -G),
            valid while |f| <= mu_v N, so x'' = (G - sgn(x') mu_r N) / (1 + kappa),
with slip = x' - q r (s - omega) and q = (z x nf).u = +-1. These are the laws of
analytic/vane_slide.py; here they are integrated by fourth-order steps that end at the
first event inside them (found on the re-integrated path): N = 0 (it leaves the
face), slip = 0 (it may roll), the friction limit while rolling, x' = 0 on the disc,
the end of the flat face (tip or inner end), the centre reaching the disc radius, and
(with mu_r > 0) w = 0: a sliding granule's spin then stays with the vane if the
resistance can hold it (mu_r >= mu_v: the sliding limit), else turns through.
"""

from __future__ import annotations

from spreadgym.physics.compiled.event_root import MAX_ITERATIONS, illinois_step
from spreadgym.physics.compiled.layout import (
    DISC_RADIUS,
    GRAVITY,
    INV_KAPPA,
    MU_DISC,
    MU_ROLL,
    MU_VANE,
    NX,
    NY,
    OMEGA,
    PX,
    PY,
    UX,
    UY,
)
from spreadgym.physics.compiled.options import INLINED, KERNEL

NONE = 0
LEAVE_NORMAL = 1  # N reached 0
SLIP_CHANGE = 2  # sliding: slip reached 0; rolling: friction limit reached
STOPPED = 3  # x' reached 0 on the disc
END_OF_FACE = 4  # tip or inner end
RIM = 5
SPIN_STOP = 6  # the spin relative to the vane reached 0 (only with rolling resistance)
EVENTS = 6


@KERNEL
def face_frame(vane, side, reach, V):
    """(px, py, ux, uy, nfx, nfy, q) of one face of a vane, for the centre line at `reach`."""
    nfx, nfy = side * V[vane, NX], side * V[vane, NY]
    ux, uy = V[vane, UX], V[vane, UY]
    q = -nfy * ux + nfx * uy
    return V[vane, PX] + reach * nfx, V[vane, PY] + reach * nfy, ux, uy, nfx, nfy, q


@KERNEL
def forces(x, xd, s, sticking, eps, rho, drag_sign, frame, radius, P):
    """(x'', s', N, f, G): acceleration along the face, spin rate, normal force, vane
    friction and the along-face force without it (all per unit mass). `rho`: sgn(s - omega)
    in this phase for the rolling resistance; 0 while the resistance holds the spin."""
    px, py, ux, uy, nfx, nfy, q = frame
    omega = P[OMEGA]
    cx, cy = px + x * ux, py + x * uy
    om2 = omega * omega
    fx = om2 * cx + 2.0 * omega * xd * uy
    fy = om2 * cy - 2.0 * omega * xd * ux
    normal = -(fx * nfx + fy * nfy)
    along = fx * ux + fy * uy - drag_sign * P[MU_DISC] * P[GRAVITY]
    inv_kappa = P[INV_KAPPA]
    resist = rho * P[MU_ROLL] * max(normal, 0.0)
    if sticking:
        f = -(along + q * resist * inv_kappa) / (1.0 + inv_kappa)
    else:
        f = -eps * P[MU_VANE] * max(normal, 0.0)
    spin_rate = 0.0 if rho == 0.0 else -(q * f + resist) * inv_kappa / radius
    return along + f, spin_rate, normal, f, along


@KERNEL
def slip(xd, s, frame, radius, omega):
    """Slip speed of the contact point along u."""
    return xd - frame[6] * radius * (s - omega)


@KERNEL
def _rk4(x, xd, s, h, sticking, eps, rho, drag_sign, frame, radius, P):
    a1, w1, _, _, _ = forces(x, xd, s, sticking, eps, rho, drag_sign, frame, radius, P)
    hh = 0.5 * h
    a2, w2, _, _, _ = forces(x + hh * xd, xd + hh * a1, s + hh * w1, sticking, eps, rho, drag_sign, frame, radius, P)
    a3, w3, _, _, _ = forces(x + hh * (xd + hh * a1), xd + hh * a2, s + hh * w2, sticking, eps, rho, drag_sign,
                             frame, radius, P)
    a4, w4, _, _, _ = forces(x + h * (xd + hh * a2), xd + h * a3, s + h * w3, sticking, eps, rho, drag_sign,
                             frame, radius, P)
    h6 = h / 6.0
    x_new = x + h * xd + h * h6 * (a1 + a2 + a3)
    return x_new, xd + h6 * (a1 + 2.0 * a2 + 2.0 * a3 + a4), s + h6 * (w1 + 2.0 * w2 + 2.0 * w3 + w4)


@KERNEL
def _event_values(out, x, xd, s, sticking, eps, rho, drag_sign, frame, radius, length, P):
    """Event functions (positive while the phase holds) into out[0:EVENTS]."""
    _, _, normal, f, _ = forces(x, xd, s, sticking, eps, rho, drag_sign, frame, radius, P)
    mu_n = P[MU_VANE] * max(normal, 0.0)
    out[0] = normal + 1e-9 * P[OMEGA] * P[OMEGA] * P[DISC_RADIUS]
    if sticking:
        out[1] = mu_n - abs(f)
    elif rho == 0.0 and drag_sign != 0.0:
        out[1] = 1.0  # held spin: the slip is x', whose zero on the disc is the x' = 0 event
    else:
        out[1] = eps * slip(xd, s, frame, radius, P[OMEGA])
    out[2] = drag_sign * xd if drag_sign != 0.0 else 1.0
    out[3] = min(x, length - x)
    cx, cy = frame[0] + x * frame[2], frame[1] + x * frame[3]
    r = P[DISC_RADIUS]
    out[4] = r * r - cx * cx - cy * cy
    out[5] = rho * (s - P[OMEGA]) if rho != 0.0 and P[MU_ROLL] > 0.0 else 1.0


@INLINED
def step(x, xd, s, h, sticking, eps, rho, drag_sign, frame, radius, length, P, work):
    """Advance up to h s along the face. Returns (x, x', s, time used, event)."""
    start, end = work[0], work[1]
    _event_values(start, x, xd, s, sticking, eps, rho, drag_sign, frame, radius, length, P)
    ex, exd, es = _rk4(x, xd, s, h, sticking, eps, rho, drag_sign, frame, radius, P)
    _event_values(end, ex, exd, es, sticking, eps, rho, drag_sign, frame, radius, length, P)
    best, which = 2.0, -1
    for j in range(EVENTS):
        if end[j] < 0.0:
            f = max(start[j], 0.0) / (max(start[j], 0.0) - end[j])
            if f < best:
                best, which = f, j
    if which < 0:
        return ex, exd, es, h, NONE
    lo, hi, g_lo, g_hi, f = 0.0, 1.0, max(start[which], 0.0), end[which], best
    moved = 0
    for _ in range(MAX_ITERATIONS):
        mx, mxd, ms = _rk4(x, xd, s, f * h, sticking, eps, rho, drag_sign, frame, radius, P)
        _event_values(end, mx, mxd, ms, sticking, eps, rho, drag_sign, frame, radius, length, P)
        lo, hi, g_lo, g_hi, f, converged, moved = illinois_step(lo, hi, g_lo, g_hi, f, end[which], moved)
        if converged:
            break
    ex, exd, es = _rk4(x, xd, s, f * h, sticking, eps, rho, drag_sign, frame, radius, P)
    return ex, exd, es, f * h, (LEAVE_NORMAL, SLIP_CHANGE, STOPPED, END_OF_FACE, RIM, SPIN_STOP)[which]
