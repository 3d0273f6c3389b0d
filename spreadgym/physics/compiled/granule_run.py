"""One granule from the vane-top level to the rim: the event loop over the phases.

Each granule is an independent small problem (granules never touch each other). The
loop advances it by steps of at most P[STEP], cut at the vertical events
(vertical_events), in one of two phases: free (free_motion) or pressed on a vane face
(face_motion). Contacts change the phase:
  * reaching a face, or an overlap with a vane found at the end of a step: an impact
    (contact_law.impact, vane restitution and friction). Every rebound is followed
    until its flight would be shorter than the full model's time step; that impact is
    plastic, and on a flat face that the frame's forces press the granule against it
    starts the contact phase;
  * a granule that comes down onto a vane (released onto it, or falling below the vane
    tops over it) is pushed off as the full model's overlap correction does it: only
    the position moves (the velocity in the machine frame is kept), by the overlap less
    what the granule's own motion away from the vane clears at that correction's rate;
    an approaching one first has its impact, at the vane's surface point;
  * a disc impact: the Coulomb friction impulse mu_d J_n against the velocity
    relative to the disc (never reversing it), J_n = (1 + e) v at a rebound and v when
    the granule comes to rest;
  * a face phase ends when N reaches 0, at the end of the flat face, or when the
    granule rises above the vane tops (it then passes over the vanes).
Outcomes and state are those of the pymunk model (departure.py codes; state in the
frame of the disc at time t).
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from spreadgym.physics.compiled import face_motion, free_motion, vertical_events
from spreadgym.physics.compiled.contact_law import disc_drag_impulse, frame_acceleration, impact
from spreadgym.physics.compiled.layout import (
    E_DISC,
    E_VANE,
    GRAVITY,
    HALF_THICKNESS,
    INV_KAPPA,
    LENGTH,
    MU_DISC,
    MU_ROLL,
    MU_VANE,
    NX,
    NY,
    OMEGA,
    OVERLAP_RATE,
    REBOUND_FLIGHT,
    SETTLE_SPEED,
    STEP,
    STUCK_SPEED,
    TIME_LIMIT,
    VANE_TOP,
)
from spreadgym.physics.compiled.options import INLINED, KERNEL, PARALLEL
from spreadgym.physics.departure import DEPARTED, RETAINED_STUCK, RETAINED_TIMEOUT

MAX_LOOPS = 200_000  # guard: a granule still looping after this many events counts as timed out
MAX_STALLED = 1000  # guard: this many events in a row that together advance time by no more
STALL_FRACTION = 1e-6  # than this fraction of the largest step (P[STEP]) end the run (flagged).
# A tolerance, not an exact zero: rounding (an FMA-contracted build) can leave each
# stalled event a time of 1e-17 s instead of 0, which an exact test would take for progress.
# Columns of the output state; STALLED is 1 for a run a guard ended, LOOPS its loop passes.
CX, CY, VX, VY, SPIN, Z, VZ, TIME, STALLED, LOOPS = range(10)
OUT_SIZE = 10


@INLINED
def _resist_spin(s, omega, normal_impulse, radius, P):
    """The spin after the vane's rolling resistance acts through a normal impulse (per unit
    mass): an angular impulse of at most mu_r r J_n against s - omega, which it never reverses."""
    if P[MU_ROLL] <= 0.0:
        return s
    most = P[MU_ROLL] * normal_impulse * P[INV_KAPPA] / radius
    w = s - omega
    if abs(w) <= most:
        return omega
    return s - math.copysign(most, w)


@INLINED
def _catch(cx, cy, vx, vy, s, nx, ny, radius, P):
    """Impact on a surface of normal n; (vx, vy, s, stays in contact). A rebound whose
    flight back (2 e a / press) would be shorter than P[REBOUND_FLIGHT] ends the
    bouncing: that impact is plastic, and the granule stays on a face the frame presses
    it on. The rolling resistance acts through the impact's normal impulse after its friction."""
    omega = P[OMEGA]
    bx, by, bs, approach = impact(vx, vy, s, nx, ny, radius, omega, P[E_VANE], P[MU_VANE], P[INV_KAPPA])
    if approach <= 0.0:
        return vx, vy, s, False
    px, py, ps, _ = impact(vx, vy, s, nx, ny, radius, omega, 0.0, P[MU_VANE], P[INV_KAPPA])
    ax, ay = frame_acceleration(cx, cy, px, py, omega)
    press = -(ax * nx + ay * ny)
    if press > 0.0 and 2.0 * P[E_VANE] * approach < press * P[REBOUND_FLIGHT]:
        return px, py, _resist_spin(ps, omega, approach, radius, P), True
    return bx, by, _resist_spin(bs, omega, (1.0 + P[E_VANE]) * approach, radius, P), False


@INLINED
def _rolling_or_sliding(x, xd, s, drag_sign, frame, radius, P, slip_is_zero):
    """(sticking, eps, rho, x') for a granule on a face: it rolls (no slip) if it does not
    slip and friction can hold that; otherwise it slides against its slip. `slip_is_zero`:
    the slip has just reached 0; its remainder (the error of the located event) is
    taken off x' so the new phase starts exactly at zero slip. rho: the sign of the spin
    relative to the vane that the rolling resistance opposes (`_sliding_spin_sign`)."""
    omega = P[OMEGA]
    q = frame[6]
    sl = face_motion.slip(xd, s, frame, radius, omega)
    tol = 1e-9 * (abs(xd) + radius * abs(omega))
    if not slip_is_zero and abs(sl) > tol:
        eps = math.copysign(1.0, sl)
        return False, eps, _sliding_spin_sign(s, omega, q, eps, P), xd
    xd -= sl
    # rolling: w = x' / (q r), or from rest the way the face's force drives it
    drive = xd
    if drive == 0.0:
        _, _, _, _, drive = face_motion.forces(x, xd, s, True, 1.0, 0.0, drag_sign, frame, radius, P)
    roll = q * math.copysign(1.0, drive)
    _, _, normal, f, _ = face_motion.forces(x, xd, s, True, 1.0, roll, drag_sign, frame, radius, P)
    if abs(f) <= P[MU_VANE] * max(normal, 0.0):
        return True, 1.0, roll, xd
    eps = -math.copysign(1.0, f)
    return False, eps, _sliding_spin_sign(s, omega, q, eps, P), xd


@INLINED
def _sliding_spin_sign(s, omega, q, eps, P):
    """rho of a sliding granule: sgn(s - omega); at s = omega, 0 (held) if the rolling
    resistance can hold the spin against the friction's torque (mu_r >= mu_v), else the
    way that torque turns it (q eps)."""
    w = s - omega
    if w != 0.0 or P[MU_ROLL] <= 0.0:
        return math.copysign(1.0, w) if w != 0.0 else q * eps
    return 0.0 if P[MU_VANE] <= P[MU_ROLL] else q * eps


@INLINED
def _drag_sign(x, xd, frame, resting, P):
    """Direction of the disc's drag along the face (0 in the air); at x' = 0 it opposes the pull."""
    if not resting:
        return 0.0
    if xd != 0.0:
        return math.copysign(1.0, xd)
    omega = P[OMEGA]
    pull = omega * omega * ((frame[0] + x * frame[2]) * frame[2] + (frame[1] + x * frame[3]) * frame[3])
    return math.copysign(1.0, pull)


@KERNEL
def run_one(cx, cy, radius, z, vz, P, V, out, track):
    """`follow` with its scratch array allocated here (on the CPU)."""
    return follow(cx, cy, radius, z, vz, P, V, out, track, np.empty((2, face_motion.EVENTS)))


@KERNEL
def follow(cx, cy, radius, z, vz, P, V, out, track, work):
    """Follow one granule (start at rest in the machine frame at (cx, cy), base height z,
    vertical speed vz); write its final state into `out`, its path into `track`
    (rows of positions in the disc frame and times; NaN-padded). Returns its outcome.
    `work` (2, face_motion.EVENTS): scratch space (a GPU thread's local array there)."""
    omega, g, top = P[OMEGA], P[GRAVITY], P[VANE_TOP]
    reach = radius + P[HALF_THICKNESS]
    vx, vy, s = omega * cy, -omega * cx, 0.0
    resting = z <= 0.0
    if resting:
        z, vz = 0.0, 0.0
    below = z < top
    t = 0.0
    on_face, entering, vane, side, sticking, eps, rho = False, False, -1, 0.0, False, 1.0, 1.0
    frame = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    x, xd, length = 0.0, 0.0, 0.0
    outcome = RETAINED_TIMEOUT
    n_track = track.shape[0]
    stalled, loop = 0, 0
    stall_time = STALL_FRACTION * P[STEP]
    progress_mark = 0.0  # the time at the last event that moved it on by more than stall_time
    check_overlap = below  # released onto a vane: pushed off it before anything moves
    came_down = below  # the overlap to check is one of a granule that came down onto a vane
    clearing = -1  # a vane the granule came down onto that moves away from it, until it is clear
    for loop in range(MAX_LOOPS):
        if check_overlap:
            check_overlap = False
            k, sd, nx, ny, depth = free_motion.overlap(cx, cy, reach, V)
            if k < 0:
                clearing = -1
            elif k == clearing:
                pass  # still clearing the vane it came down onto: no push
            elif came_down:
                # Come down onto a vane: as in the full model, the impact (if it approaches)
                # takes the velocity of the vane's surface point, `depth` deeper than the
                # granule's: the velocity in this frame at the centre pushed off by `depth`
                # (-omega z x the shift; the velocity in the machine frame is kept). Then
                # the push along the contact normal as the full model's overlap correction
                # makes it, at the rate P[OVERLAP_RATE] (a fraction of the overlap per unit
                # time), while the granule, moving away from the vane at `away`, clears
                # the rest itself: the shift is depth - away T, T the time until it is clear.
                separating = vx * nx + vy * ny > 0.0
                vx, vy = vx + omega * depth * ny, vy - omega * depth * nx
                vx, vy, s, stays = _catch(cx + depth * nx, cy + depth * ny, vx, vy, s, nx, ny, radius, P)
                away = vx * nx + vy * ny
                shift = depth
                if away > 0.0 and not stays:
                    rate = P[OVERLAP_RATE]
                    shift = depth - away * math.log1p(rate * depth / away) / rate
                    if separating:
                        clearing = k
                back = depth - shift
                vx, vy = vx - omega * back * ny, vy + omega * back * nx
                cx, cy = cx + shift * nx, cy + shift * ny
                entering = stays and sd != 0.0
                if entering:
                    vane, side = k, sd
            elif k >= 0:
                # pressed into a vane after a step (a rounded end): pushed off, then the
                # impact; only the position is corrected (velocity in the machine frame kept,
                # so the velocity in this turning frame changes by -omega z x the shift)
                cx, cy = cx + depth * nx, cy + depth * ny
                vx, vy = vx + omega * depth * ny, vy - omega * depth * nx
                vx, vy, s, stays = _catch(cx, cy, vx, vy, s, nx, ny, radius, P)
                entering = stays and sd != 0.0
                if entering:
                    vane, side = k, sd
            came_down = False
        if entering:
            on_face, entering = True, False
            frame = face_motion.face_frame(vane, side, reach, V)
            length = V[vane, LENGTH]
            x = (cx - frame[0]) * frame[2] + (cy - frame[1]) * frame[3]
            xd = vx * frame[2] + vy * frame[3]
            cx, cy = frame[0] + x * frame[2], frame[1] + x * frame[3]
            vx, vy = xd * frame[2], xd * frame[3]
            sticking, eps, rho, xd = _rolling_or_sliding(x, xd, s, _drag_sign(x, xd, frame, resting, P), frame,
                                                         radius, P, False)
        if loop < n_track:
            track[loop, 0], track[loop, 1], track[loop, 2] = cx, cy, t
        if t >= P[TIME_LIMIT]:
            break
        h, vertical = vertical_events.next_event(z, vz, resting, below, top, g, min(P[STEP], P[TIME_LIMIT] - t))
        full = True
        if on_face:
            drag_sign = _drag_sign(x, xd, frame, resting, P)
            x, xd, s, used, event = face_motion.step(x, xd, s, h, sticking, eps, rho, drag_sign, frame, radius,
                                                     length, P, work)
            cx, cy = frame[0] + x * frame[2], frame[1] + x * frame[3]
            vx, vy = xd * frame[2], xd * frame[3]
            full = event == face_motion.NONE
            if event == face_motion.RIM:
                outcome = DEPARTED
            elif event == face_motion.LEAVE_NORMAL or event == face_motion.END_OF_FACE:
                on_face = False
            elif event == face_motion.SLIP_CHANGE:
                if sticking:  # the friction limit: it slides on, its spin still turning the same way
                    _, _, _, f, _ = face_motion.forces(x, xd, s, True, 1.0, rho, drag_sign, frame, radius, P)
                    sticking, eps = False, -math.copysign(1.0, f)
                else:
                    sticking, eps, rho, xd = _rolling_or_sliding(x, xd, s, drag_sign, frame, radius, P, True)
            elif event == face_motion.SPIN_STOP:
                s = omega  # the spin relative to the vane reached 0 (rolling: so did x')
                if sticking:
                    sticking, eps, rho, xd = _rolling_or_sliding(x, xd, s, drag_sign, frame, radius, P, True)
                else:
                    rho = _sliding_spin_sign(s, omega, frame[6], eps, P)
            elif event == face_motion.STOPPED:
                xd, vx, vy = 0.0, 0.0, 0.0
                pull = omega * omega * (cx * frame[2] + cy * frame[3])
                if abs(pull) <= P[MU_DISC] * g:
                    outcome = RETAINED_STUCK
                else:
                    sticking, eps, rho, xd = _rolling_or_sliding(x, xd, s, _drag_sign(x, xd, frame, resting, P),
                                                                 frame, radius, P, False)
        else:
            drag = P[MU_DISC] * g if resting else 0.0
            cx, cy, vx, vy, used, event, k, sd = free_motion.step(cx, cy, vx, vy, h, below, drag, reach, P, V)
            full = event == free_motion.NONE
            if event == free_motion.RIM:
                outcome = DEPARTED
            elif event == free_motion.FACE:
                nx, ny = sd * V[k, NX], sd * V[k, NY]
                vx, vy, s, stays = _catch(cx, cy, vx, vy, s, nx, ny, radius, P)
                entering = stays
                if stays:
                    vane, side = k, sd
            elif event == free_motion.END_CAP:
                ex, ey = free_motion.end_point(k, sd, V)
                gap = math.sqrt((cx - ex) ** 2 + (cy - ey) ** 2)
                nx, ny = (cx - ex) / gap, (cy - ey) / gap
                # exactly on the cap: a granule the frame keeps pressing on it is then
                # not a new crossing at the next step but an overlap at its end
                cx, cy = ex + reach * nx, ey + reach * ny
                vx, vy, s, _ = _catch(cx, cy, vx, vy, s, nx, ny, radius, P)
            elif resting and omega * omega * math.sqrt(cx * cx + cy * cy) < P[MU_DISC] * g:
                if math.sqrt(vx * vx + vy * vy) < P[STUCK_SPEED] + 2.0 * P[MU_DISC] * g * h:
                    outcome = RETAINED_STUCK
        z, vz = vertical_events.advance(z, vz, resting, used, g)
        t += used
        if t > progress_mark + stall_time:
            progress_mark, stalled = t, 0
        else:
            stalled += 1
        if stalled >= MAX_STALLED:
            break
        if outcome != RETAINED_TIMEOUT:
            break
        if full and vertical == vertical_events.DISC_IMPACT:
            vz, resting, j = vertical_events.disc_impact(vz, P[E_DISC], P[SETTLE_SPEED])
            z = 0.0
            if on_face:
                xd = math.copysign(max(abs(xd) - P[MU_DISC] * j, 0.0), xd)
                vx, vy = xd * frame[2], xd * frame[3]
                sticking, eps, rho, xd = _rolling_or_sliding(x, xd, s, _drag_sign(x, xd, frame, resting, P), frame,
                                                             radius, P, False)
            else:
                vx, vy = disc_drag_impulse(vx, vy, P[MU_DISC] * j)
        elif full and vertical == vertical_events.VANE_TOP_CROSSING:
            below = not below
            came_down = below
            if not below:
                on_face = False
        if not on_face and below and event == free_motion.NONE:
            check_overlap = True
    out[CX], out[CY], out[VX], out[VY], out[SPIN] = cx, cy, vx, vy, s
    out[Z], out[VZ], out[TIME] = z, vz, t
    out[STALLED] = 1.0 if (stalled >= MAX_STALLED or loop == MAX_LOOPS - 1) and outcome == RETAINED_TIMEOUT else 0.0
    out[LOOPS] = loop + 1
    return outcome


@PARALLEL
def run_all(start, radius, design, z0, vz0, P, V, vane_count, out, outcome, tracks):
    """Every granule of every design, in parallel over the flat (design x granule) index:
    granule i belongs to design[i], whose start height z0[d], vertical speed vz0[d],
    parameters P[d] and first vane_count[d] vane rows V[d] it runs with. Each granule is
    the same scalar `run_one` whichever thread runs it, so the bits do not depend on the
    thread count. tracks (k, T, 3) for the first k granules."""
    empty = np.empty((0, 3))
    for i in prange(start.shape[0]):
        d = design[i]
        track = tracks[i] if i < tracks.shape[0] else empty
        outcome[i] = run_one(start[i, 0], start[i, 1], radius[i], z0[d], vz0[d], P[d], V[d, :vane_count[d]], out[i],
                             track)
