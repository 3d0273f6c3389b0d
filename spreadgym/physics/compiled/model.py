"""`simulate_compiled`: the compiled model's entry point, with the frames of the pymunk model.

The run of a granule starts when it reaches the vane tops (above them nothing touches
it: the fall is exact), with the spinner turned by phase + omega t_fall; the kernel
works in the frame of the disc and reports the state there, which is turned into the
machine frame here. Same outcomes, fields and time origin as simulate_pymunk.
"""

from __future__ import annotations

from typing import Callable, Optional

import numpy as np

from spreadgym.config.scene import Scene
from spreadgym.physics.compiled import granule_run
from spreadgym.physics.compiled.layout import OMEGA_STEP, STEP, pack_parameters, pack_vanes
from spreadgym.physics.contacts import Contacts
from spreadgym.physics.departure import Departure
from spreadgym.physics.granules import GranuleBatch, rotate
from spreadgym.physics.numerics import choose_time_step
from spreadgym.physics.stepped.finish import MAX_SPINNER_TIME_S, STUCK_SPEED_M_S
from spreadgym.physics.vertical import free_fall_to

MAX_TRACK_POINTS = 20_000


def simulate_compiled(
    scene: Scene,
    granules: GranuleBatch,
    contacts: Contacts,
    progress: Optional[Callable[[float], None]] = None,
    track_count: int = 0,
) -> Departure:
    """Departure states of `granules` (machine frame, SI units); `track_count` paths kept.

    Bounces (off the disc and off the vanes) are followed down to a flight as short as
    the pymunk model's time step; shorter ones end the bouncing, as they do there.
    """
    omega = scene.spinner.omega_rad_s
    vane_top = scene.vanes.height_m
    drop = scene.feed.drop_height_m
    t_fall, vz_fall = free_fall_to(vane_top, drop)
    z0 = min(drop, vane_top)
    spinner_angle = granules.phase_rad + omega * t_fall
    start = np.ascontiguousarray(rotate(granules.release_xy_m, -spinner_angle))
    resolved = choose_time_step(scene, float(granules.radius_m.min())).dt_s
    params = pack_parameters(scene, contacts, resolved, MAX_SPINNER_TIME_S, STUCK_SPEED_M_S)
    vanes = pack_vanes(scene)
    n = granules.count
    out = np.zeros((n, granule_run.OUT_SIZE))
    outcome = np.zeros(n, dtype=np.int8)
    n_track = min(track_count, n)
    tracks = np.full((n_track, MAX_TRACK_POINTS, 3), np.nan)
    radius = np.ascontiguousarray(granules.radius_m, dtype=np.float64)
    granule_run.run_all(start, radius, float(z0), float(vz_fall), params, vanes, out, outcome, tracks)
    if progress is not None:
        progress(float(out[:, granule_run.TIME].max(initial=0.0)))

    t = out[:, granule_run.TIME]
    c = out[:, [granule_run.CX, granule_run.CY]]
    v = out[:, [granule_run.VX, granule_run.VY]]
    v_inertial = v + omega * np.stack([-c[:, 1], c[:, 0]], axis=1)
    turn = spinner_angle + omega * t
    notes = [
        f"largest step {params[STEP]:.3g} s (|omega| dt = {OMEGA_STEP:g}), cut at every event "
        "(disc impacts, vane contacts, rolling/sliding changes, the rim)",
        f"free fall above the vane tops solved exactly ({t_fall * 1e3:.1f} ms)",
    ]
    stalled = int(out[:, granule_run.STALLED].sum())
    if stalled:
        notes.append(f"{stalled} granule(s) stopped by the event-loop guard, counted as timed out")
    return Departure(
        position_m=rotate(c, turn),
        velocity_m_s=rotate(v_inertial, turn),
        spin_rad_s=out[:, granule_run.SPIN].copy(),
        height_m=out[:, granule_run.Z].copy(),
        vertical_velocity_m_s=out[:, granule_run.VZ].copy(),
        time_s=t + t_fall,
        outcome=outcome,
        model="compiled",
        dt_s=float(params[STEP]),
        notes=notes,
        tracks=[_machine_track(tracks[k], spinner_angle[k], omega, rotate(c[k:k + 1], turn[k:k + 1])[0])
                for k in range(n_track)],
    )


def _machine_track(rows: np.ndarray, start_angle: float, omega: float, end: np.ndarray) -> np.ndarray:
    """A recorded path (disc-frame points with their times) in the machine frame, ending at `end`."""
    rows = rows[~np.isnan(rows[:, 0])]
    path = rotate(rows[:, :2], start_angle + omega * rows[:, 2])
    return np.vstack([path, end])
