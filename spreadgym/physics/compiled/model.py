"""`simulate_compiled`: the compiled model's entry point, with the frames of the pymunk model.

The run of a granule starts when it reaches the vane tops (above them nothing touches
it: the fall is exact), with the spinner turned by phase + omega t_fall; the kernel
works in the frame of the disc and reports the state there, which is turned into the
machine frame here. Same outcomes, fields and time origin as simulate_pymunk.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np
from numba import prange

from spreadgym import device
from spreadgym.config.scene import Scene
from spreadgym.physics.compiled import granule_run
from spreadgym.physics.compiled.layout import DISC_RADIUS, OMEGA_STEP, STEP, V_SIZE, pack_parameters, pack_vanes
from spreadgym.physics.compiled.options import KERNEL, PARALLEL
from spreadgym.physics.contacts import Contacts
from spreadgym.physics.departure import Departure
from spreadgym.physics.granules import GranuleBatch, rotate
from spreadgym.physics.numerics import choose_time_step
from spreadgym.physics.stepped.finish import MAX_SPINNER_TIME_S, STUCK_SPEED_M_S
from spreadgym.physics.vertical import free_fall_to
from spreadgym.threads import numba_threads, thread_map

MAX_TRACK_POINTS = 20_000
START_BINS = 64
"""Bins of a granule's start radius (a fraction of its disc's) for the GPU queue's order
(`longest_first`): in the schedule model (`make bench` section gpu-schedule) the kernel
times came within 1.6 % of those with a full sort by start radius."""
SORT_PARTS = 64  # parts of the order's counting sort, shared out over the threads


@dataclass(frozen=True)
class KernelInputs:
    """What the kernel takes for one scene's granules (disc frame at the vane tops), and
    the frame turns that bring its output back to the machine frame."""

    start: np.ndarray  # (N, 2) release points in the disc frame when the run starts, m
    radius: np.ndarray  # (N,) granule radii, m
    z0: float  # base height where the run starts, m
    vz0: float  # vertical speed there, m/s
    params: np.ndarray  # layout.P
    vanes: np.ndarray  # layout.V
    spinner_angle: np.ndarray  # (N,) the spinner's angle when each run starts, rad
    t_fall: float  # s from release to the vane tops


def kernel_inputs(scene: Scene, granules: GranuleBatch, contacts: Contacts) -> KernelInputs:
    """The kernel's inputs for `granules` on `scene` (SI units)."""
    vane_top = scene.vanes.height_m
    drop = scene.feed.drop_height_m
    t_fall, vz_fall = free_fall_to(vane_top, drop)
    spinner_angle = granules.phase_rad + scene.spinner.omega_rad_s * t_fall
    resolved = choose_time_step(scene, float(granules.radius_m.min())).dt_s
    return KernelInputs(
        start=np.ascontiguousarray(rotate(granules.release_xy_m, -spinner_angle)),
        radius=np.ascontiguousarray(granules.radius_m, dtype=np.float64),
        z0=float(min(drop, vane_top)),
        vz0=float(vz_fall),
        params=pack_parameters(scene, contacts, resolved, MAX_SPINNER_TIME_S, STUCK_SPEED_M_S),
        vanes=pack_vanes(scene),
        spinner_angle=spinner_angle,
        t_fall=t_fall,
    )


def run_kernels(batch: list[KernelInputs], track_count: int = 0) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(out (N, OUT_SIZE), outcome (N,), tracks (k, MAX_TRACK_POINTS, 3)) of each inputs'
    granules, all designs' granules in one parallel kernel run, on the CPU's threads or,
    where spreadgym.device says "cuda", in one GPU launch; tracks (pictures, always on the
    CPU) of the first design's first `track_count` granules."""
    arrays, counts = kernel_arrays(batch)
    n = int(counts.sum())
    out = np.zeros((n, granule_run.OUT_SIZE))
    outcome = np.zeros(n, dtype=np.int8)
    tracks = np.full((min(track_count, counts[0]), MAX_TRACK_POINTS, 3), np.nan)
    if device.current() == "cuda" and not tracks.shape[0]:
        from spreadgym.physics.compiled import cuda_spinner  # numba's CUDA target: only when asked for

        cuda_spinner.run_all(*arrays, out, outcome)
    else:
        with numba_threads():
            granule_run.run_all(*arrays, out, outcome, tracks)
    edges = np.cumsum(counts)[:-1]
    no_tracks = tracks[:0]
    return [(o, c, tracks if d == 0 else no_tracks)
            for d, (o, c) in enumerate(zip(np.split(out, edges), np.split(outcome, edges)))]


def kernel_arrays(batch: list[KernelInputs]) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
    """The kernels' arguments for a batch's granules, flat over (design x granule): start
    (N, 2), radius (N,), design (N,), z0 (D,), vz0 (D,), P (D, P_SIZE), V (D, most vanes,
    V_SIZE), vane_count (D,); and each design's granule count."""
    counts = np.array([inputs.radius.shape[0] for inputs in batch])
    vanes = np.zeros((len(batch), max(inputs.vanes.shape[0] for inputs in batch), V_SIZE))
    for d, inputs in enumerate(batch):
        vanes[d, :inputs.vanes.shape[0]] = inputs.vanes
    arrays = (np.concatenate([inputs.start for inputs in batch]), np.concatenate([inputs.radius for inputs in batch]),
              np.repeat(np.arange(len(batch)), counts),
              np.array([inputs.z0 for inputs in batch]), np.array([inputs.vz0 for inputs in batch]),
              np.stack([inputs.params for inputs in batch]), vanes,
              np.array([inputs.vanes.shape[0] for inputs in batch]))
    return arrays, counts


def longest_first(start: np.ndarray, design: np.ndarray, P: np.ndarray) -> np.ndarray:
    """The GPU queue's order of the granules (indices): those starting nearest their disc's
    axis first, in START_BINS bins of start radius over disc radius, launch order within a
    bin. A counting sort over SORT_PARTS consecutive parts on spreadgym's threads (the order
    does not depend on their count): two passes over the granules."""
    with numba_threads():
        return _counting_sort(start, design, P)


@PARALLEL
def _counting_sort(start, design, P):
    n = start.shape[0]
    parts = max(1, min(SORT_PARTS, n))
    bins = np.empty(n, dtype=np.int64)
    counts = np.zeros((parts, START_BINS), dtype=np.int64)
    for c in prange(parts):
        for i in range(c * n // parts, (c + 1) * n // parts):
            reach = math.sqrt(start[i, 0] ** 2 + start[i, 1] ** 2) / P[design[i], DISC_RADIUS]
            bins[i] = min(max(int(reach * START_BINS), 0), START_BINS - 1)
            counts[c, bins[i]] += 1
    place = np.empty((parts, START_BINS), dtype=np.int64)  # where part c's next granule of bin b goes
    filled = 0
    for b in range(START_BINS):
        for c in range(parts):
            place[c, b] = filled
            filled += counts[c, b]
    order = np.empty(n, dtype=np.int64)
    for c in prange(parts):
        for i in range(c * n // parts, (c + 1) * n // parts):
            order[place[c, bins[i]]] = i
            place[c, bins[i]] += 1
    return order


def run_kernel(inputs: KernelInputs, track_count: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`run_kernels` of one scene's granules."""
    return run_kernels([inputs], track_count)[0]


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
    inputs = kernel_inputs(scene, granules, contacts)
    out, outcome, tracks = run_kernel(inputs, track_count)
    if progress is not None:
        progress(float(out[:, granule_run.TIME].max(initial=0.0)))
    return departure_from(inputs, scene.spinner.omega_rad_s, out, outcome, tracks)


def simulate_compiled_batch(runs: list[tuple[Scene, GranuleBatch, Contacts]]) -> list[Departure]:
    """`simulate_compiled` of each (scene, granules, contacts), all granules in one parallel
    kernel run, the departure states turned to the machine frame side by side on threads
    (a GIL-free kernel each); the same bits as one call each."""
    batch = [kernel_inputs(*run) for run in runs]
    results = run_kernels(batch)
    return thread_map(lambda i: departure_from(batch[i], runs[i][0].spinner.omega_rad_s, *results[i]), len(runs))


def departure_from(inputs: KernelInputs, omega: float, out: np.ndarray, outcome: np.ndarray,
                   tracks: np.ndarray) -> Departure:
    """The departure states (machine frame) from the kernel's output for `inputs`."""
    position, velocity = machine_frame(out, inputs.spinner_angle, omega)
    params = inputs.params
    notes = [
        f"largest step {params[STEP]:.3g} s (|omega| dt = {OMEGA_STEP:g}), cut at every event "
        "(disc impacts, vane contacts, rolling/sliding changes, the rim)",
        f"free fall above the vane tops solved exactly ({inputs.t_fall * 1e3:.1f} ms)",
    ]
    stalled = int(out[:, granule_run.STALLED].sum())
    if stalled:
        notes.append(f"{stalled} granule(s) stopped by the event-loop guard, counted as timed out")
    return Departure(
        position_m=position,
        velocity_m_s=velocity,
        spin_rad_s=out[:, granule_run.SPIN].copy(),
        height_m=out[:, granule_run.Z].copy(),
        vertical_velocity_m_s=out[:, granule_run.VZ].copy(),
        time_s=out[:, granule_run.TIME] + inputs.t_fall,
        outcome=outcome,
        model="compiled",
        dt_s=float(params[STEP]),
        notes=notes,
        tracks=[_machine_track(tracks[k], inputs.spinner_angle[k], omega, position[k]) for k in range(tracks.shape[0])],
    )


@KERNEL
def machine_frame(out, spinner_angle, omega):
    """(position (N, 2), velocity (N, 2)) in the machine frame from the kernel's
    disc-frame output: the disc-frame velocity plus omega x r, both turned by the spinner's
    angle at departure, spinner_angle + omega t, as `granules.rotate` turns them (the same
    bits where numpy's cos and sin are the C library's, as on the machines measured). One
    GIL-free pass: a batch turns its runs' states side by side."""
    n = out.shape[0]
    position, velocity = np.empty((n, 2)), np.empty((n, 2))
    for i in range(n):
        cx, cy = out[i, granule_run.CX], out[i, granule_run.CY]
        vx, vy = out[i, granule_run.VX] + omega * -cy, out[i, granule_run.VY] + omega * cx
        turn = spinner_angle[i] + omega * out[i, granule_run.TIME]
        c, s = math.cos(turn), math.sin(turn)
        position[i, 0], position[i, 1] = c * cx - s * cy, s * cx + c * cy
        velocity[i, 0], velocity[i, 1] = c * vx - s * vy, s * vx + c * vy
    return position, velocity


def _machine_track(rows: np.ndarray, start_angle: float, omega: float, end: np.ndarray) -> np.ndarray:
    """A recorded path (disc-frame points with their times) in the machine frame, ending at `end`."""
    rows = rows[~np.isnan(rows[:, 0])]
    path = rotate(rows[:, :2], start_angle + omega * rows[:, 2])
    return np.vstack([path, end])
