"""Where the numerical methods fail, and the guards that keep spreadgym on the safe side.

Four failure modes, each a pure function returning arrays (the tests run small
versions; `plot_stability_map` draws all four on one figure and writes its data):

a. pymunk tunnelling: Chipmunk has no continuous collision detection. A vane that
   moves further than the granule radius plus its half thickness within one step
   can jump over a granule. Measured on a minimal pymunk space built here (a
   kinematic spinner with one vane and granules at rest at r = 0.1 m), over a grid
   of time step x rpm. Guard: `physics.numerics.choose_time_step` (limit
   (r + t/2) / (|omega| R_vane), automatic step half of it or less).
b. spring-damper blow-up: the explicit contact is stable only below
   (2 / omega_n)(sqrt(1 + zeta^2) - zeta). The paper's printed Table 3 stiffnesses
   with the granule masses, impact by impact, with the model's own scheme
   (`physics.stepped.spring_damper.impact_rebound`). Guard: `choose_spring_damper_step`.
c. disc-friction chatter: a Coulomb impulse of mu g dt applied in full reverses a
   relative velocity smaller than itself, so a granule that should stick on the disc
   rattles. Guard: `friction_velocity_change(..., limit_to_sticking=True)`.
d. flight step error: fixed-step RK4 against the tight-tolerance reference over the
   step h. Guard: the default adaptive Dormand-Prince solver of `flight.fly`.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import pymunk

from spreadgym.config.materials import MaterialLibrary, load_library
from spreadgym.config.scene import Flight, Scene, load_scene
from spreadgym.physics.calibration import critical_time_step, damping_ratio, paper_table_consistency, sphere_mass
from spreadgym.physics.disc_friction import disc_surface_velocity, friction_velocity_change
from spreadgym.physics.numerics import choose_time_step, collision_bias_for, tunnelling_limit_s
from spreadgym.physics.stepped.spring_damper import CONTACT_STEPS, CRITICAL_SAFETY, impact_rebound
from spreadgym.physics.vertical import GRAVITY_M_S2
from spreadgym.spread import flight as flight_model

PAPER_DT_S = 5e-5  # the time step the seed paper used in RecurDyn
PUSHED_FRACTION = 0.5  # a granule counts as pushed when it moves on at >= this x omega r

# --- a. pymunk tunnelling ------------------------------------------------------------------


def _paper_scene(rpm: float) -> Scene:
    return load_scene("paper", {"spinner.rpm": float(rpm)})


def pymunk_tunnelling_fraction(
    rpm: float,
    dt_s: float,
    granules: int = 16,
    at_radius_m: float = 0.1,
    granule_radius_m: float = 0.0015,
    scene: Optional[Scene] = None,
) -> float:
    """Fraction of granules one vane passes through without pushing them.

    A minimal pymunk space, set up as the pymunk model's (kinematic spinner turning at
    `rpm`, one radial vane of the scene's length and thickness, slop 1e-5 m, bias from
    `collision_bias_for`, 10 iterations, the pair's restitution and friction), holds
    `granules` circles at rest at `at_radius_m`, ahead of the vane. Their angles are
    spread over one step's sweep, so they sample every phase of the step grid. After
    the vane has swept past them all, a granule was pushed if its velocity along the
    direction of rotation is at least PUSHED_FRACTION x omega r; otherwise the vane
    went through it (or knocked it backwards).
    """
    scene = scene if scene is not None else _paper_scene(rpm)
    omega = float(rpm) * 2.0 * math.pi / 60.0
    space = pymunk.Space()
    space.iterations = 10
    space.collision_slop = 1e-5
    space.collision_bias = collision_bias_for(dt_s)
    spinner = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    spinner.angular_velocity = omega
    half = 0.5 * scene.vanes.thickness_m
    vane = pymunk.Segment(spinner, (scene.vanes.inner_radii_m()[0], 0.0), (scene.vane_outer_radius_m, 0.0), half)
    vane.elasticity, vane.friction = 0.43, 0.52  # compound fertilizer on MC (the paper scene)
    vane.filter = pymunk.ShapeFilter(categories=0b10, mask=0b01)
    space.add(spinner, vane)
    reach = granule_radius_m + half
    first = 2.0 * reach / at_radius_m + 0.05  # clear of the vane at the start
    sweep = omega * dt_s  # the vane's turn per step
    angles = first + (np.arange(granules) + 0.5) / granules * sweep
    bodies = []
    for angle in angles:
        body = pymunk.Body(1e-5, math.inf)
        body.position = (at_radius_m * math.cos(angle), at_radius_m * math.sin(angle))
        shape = pymunk.Circle(body, granule_radius_m)
        shape.elasticity, shape.friction = 1.0, 1.0
        shape.filter = pymunk.ShapeFilter(group=1, categories=0b01, mask=0b10)
        space.add(body, shape)
        bodies.append(body)
    steps = int(math.ceil((angles[-1] + 0.3) / sweep)) + 1
    for _ in range(steps):
        space.step(dt_s)
    pushed = 0
    for body in bodies:
        x, y = body.position
        vx, vy = body.velocity
        forward = (-y * vx + x * vy) / max(math.hypot(x, y), 1e-12)
        pushed += forward >= PUSHED_FRACTION * omega * at_radius_m
    return 1.0 - pushed / granules


def tunnelling_map(rpms: Sequence[float], steps_s: Sequence[float], granules: int = 16,
                   at_radius_m: float = 0.1) -> np.ndarray:
    """`pymunk_tunnelling_fraction` over rpm (rows) x time step (columns)."""
    return np.array([[pymunk_tunnelling_fraction(rpm, dt, granules, at_radius_m) for dt in steps_s]
                     for rpm in rpms])


def tunnelling_limits(rpms: Sequence[float], granule_radius_m: float = 0.0015,
                      at_radius_m: float = 0.1) -> dict[str, np.ndarray]:
    """Per rpm: the guard's limit (vane tip), the same formula at `at_radius_m`, and the
    pymunk model's automatic step (paper scene, granules of `granule_radius_m`)."""
    guard, local, auto = [], [], []
    for rpm in rpms:
        scene = _paper_scene(rpm)
        limit = tunnelling_limit_s(scene, granule_radius_m)
        guard.append(limit)
        local.append(limit * scene.vane_outer_radius_m / at_radius_m)
        auto.append(choose_time_step(scene, granule_radius_m).dt_s)
    return {"guard_limit_s": np.array(guard), "limit_at_radius_s": np.array(local), "automatic_s": np.array(auto)}


# --- b. spring-damper blow-up ---------------------------------------------------------------


@dataclass(frozen=True)
class TableContact:
    """A printed Table 3 stiffness with a granule mass; damping from the row's restitution."""

    label: str
    mass_kg: float
    stiffness_n_per_m: float
    damping_ns_per_m: float  # 2 zeta(e) sqrt(k m): the rebound ratio of the exact contact is e
    restitution: float
    measured_contact_time_s: float
    contact_time_s: float  # pi / omega_d of this k and m (differs from the measured one)
    critical_s: float  # (2 / omega_n)(sqrt(1 + zeta^2) - zeta)
    guarded_s: float  # what the guard would use: min(contact time / 50, 0.5 x critical)


def table_contact(label: str, mass_kg: float, stiffness_n_per_m: float, restitution: float,
                  measured_contact_time_s: float) -> TableContact:
    zeta = damping_ratio(restitution)
    damping = 2.0 * zeta * math.sqrt(stiffness_n_per_m * mass_kg)
    omega_n = math.sqrt(stiffness_n_per_m / mass_kg)
    contact_time = math.pi / (omega_n * math.sqrt(1.0 - zeta * zeta))
    critical = critical_time_step(mass_kg, stiffness_n_per_m, damping)
    guarded = min(contact_time / CONTACT_STEPS, CRITICAL_SAFETY * critical)
    return TableContact(label, mass_kg, stiffness_n_per_m, damping, restitution, measured_contact_time_s,
                        contact_time, critical, guarded)


def table3_contacts(library: Optional[MaterialLibrary] = None) -> list[TableContact]:
    """Every printed Table 3 row with the mass of the library's d50 granule, plus the
    stiffest row (pellet/steel) with the 660 mg its printed numbers imply."""
    lib = library if library is not None else load_library()
    out = []
    for row in paper_table_consistency(lib):
        fert = lib.fertilizer(row.fertilizer)
        mass = sphere_mass(fert.size.d50_m, fert.particle_density_kg_m3)
        name = "compound" if row.fertilizer.startswith("compound") else row.fertilizer
        out.append(table_contact(f"{name}/{row.surface} {mass * 1e6:.0f} mg", mass, row.paper_stiffness_n_per_m,
                                 row.restitution, row.contact_time_s))
    stiffest = max(paper_table_consistency(lib), key=lambda r: r.paper_stiffness_n_per_m)
    implied = stiffest.mass_from_stiffness_kg
    out.append(table_contact(f"pellet/steel {implied * 1e6:.0f} mg (implied)", implied,
                             stiffest.paper_stiffness_n_per_m, stiffest.restitution, stiffest.contact_time_s))
    return out


def rebound_over_steps(contact: TableContact, steps_s: Sequence[float], phases: int = 16) -> dict[str, np.ndarray]:
    """Rebound ratio v_out / v_in of one impact per entry phase, for each step:
    mean, min, max over the phases, and the largest energy gain during contact."""
    alpha = (np.arange(phases) + 0.5) / phases
    mean, low, high, gain = [], [], [], []
    for dt in steps_s:
        ratio, _, peak = impact_rebound(contact.stiffness_n_per_m, contact.damping_ns_per_m, contact.mass_kg,
                                        float(dt), alpha)
        mean.append(ratio.mean())
        low.append(ratio.min())
        high.append(ratio.max())
        gain.append(peak.max())
    return {"mean": np.array(mean), "min": np.array(low), "max": np.array(high), "energy_gain": np.array(gain)}


# --- c. disc-friction chatter -------------------------------------------------------------


def disc_friction_chatter(
    guarded: bool,
    steps: int = 80,
    rpm: float = 40.0,
    radius_m: float = 0.05,
    friction: float = 0.52,
    dt_s: Optional[float] = None,
) -> dict[str, np.ndarray]:
    """A granule dropped at rest on a slow disc (omega^2 r < mu g: it should end up
    carried along, stuck) under the disc's Coulomb drag, stepped like the spinner
    models (velocity change from `friction_velocity_change` with the resting normal
    impulse g dt, then x += v dt). `dt_s` None: the pymunk model's automatic step for
    the paper scene at `rpm`.

    Returns per step (at the start of each step): the slip relative to the disc along
    the direction of rotation (`slip_tangential`) and outwards (`slip_radial`), m/s.
    """
    omega = float(rpm) * 2.0 * math.pi / 60.0
    dt = dt_s if dt_s is not None else choose_time_step(_paper_scene(rpm), 0.0015).dt_s
    x = np.array([[radius_m, 0.0]])
    v = np.zeros((1, 2))
    impulse = np.array([GRAVITY_M_S2 * dt])
    tangential, radial = [], []
    for _ in range(steps):
        rel = v - disc_surface_velocity(x, omega)
        r = float(np.hypot(*x[0]))
        e_r = x[0] / r
        e_t = np.array([-e_r[1], e_r[0]]) * math.copysign(1.0, omega)
        tangential.append(float(rel[0] @ e_t))
        radial.append(float(rel[0] @ e_r))
        v = v + friction_velocity_change(x, v, omega, friction, impulse, limit_to_sticking=guarded)
        x = x + dt * v
    return {
        "step": np.arange(steps),
        "slip_tangential": np.array(tangential),
        "slip_radial": np.array(radial),
        "dt_s": np.array(dt),
        "coulomb_dv": np.array(friction * GRAVITY_M_S2 * dt),  # mu g dt
        "drift": np.array(omega * omega * radius_m * dt),  # omega^2 r dt, one step of centripetal motion
    }


# --- d. flight step error -----------------------------------------------------------------


def _flight_launches(speeds_m_s: Sequence[float], elevations_deg: Sequence[float]):
    v = []
    for speed in speeds_m_s:
        for elev in elevations_deg:
            a = math.radians(elev)
            v.append([speed * math.cos(a), 0.0, speed * math.sin(a)])
    v = np.array(v)
    n = v.shape[0]
    density = load_library().fertilizer_of(load_scene("paper")).particle_density_kg_m3  # configs/materials.yaml
    return np.zeros((n, 2)), np.full(n, 0.8), v, np.full(n, 0.003), np.full(n, density)


def flight_step_errors(
    steps_s: Sequence[float],
    speeds_m_s: Sequence[float] = (10.0, 20.0, 30.0, 40.0),
    elevations_deg: Sequence[float] = (-10.0, 0.0, 15.0),
    flight: Optional[Flight] = None,
) -> dict[str, np.ndarray]:
    """Largest landing-point error (m) of fixed-step RK4 (`fly(..., dt_s=h)`) against
    `reference_landing` for each h, and that of the default adaptive solver.

    Granules: 3 mm compound fertilizer launched 0.8 m above the ground at each speed and
    elevation. Also returns RK4's linear stability limit 2.785 / (2 K |v|) at the
    fastest launch (the drag Jacobian's largest eigenvalue is about 2 K |v|).
    """
    flight = flight if flight is not None else Flight()
    pos, height, vel, diam, dens = _flight_launches(speeds_m_s, elevations_deg)
    ref = flight_model.reference_landing(pos, height, vel, diam, dens, flight).position_m
    errors = []
    for h in steps_s:
        got = flight_model.fly(pos, height, vel, diam, dens, flight, dt_s=float(h)).position_m
        errors.append(float(np.max(np.hypot(*(got - ref).T))))
    adaptive = flight_model.fly(pos, height, vel, diam, dens, flight).position_m
    k = float(flight_model.drag_constant(0.003, 1734.0, flight))
    flight_time = flight_model.fly(pos, height, vel, diam, dens, flight).time_s
    return {
        "h_s": np.asarray(steps_s, dtype=float),
        "rk4_error_m": np.array(errors),
        "adaptive_error_m": np.array(float(np.max(np.hypot(*(adaptive - ref).T)))),
        "rk4_stability_limit_s": np.array(2.785 / (2.0 * k * max(speeds_m_s))),
        "longest_flight_s": np.array(float(flight_time.max())),
    }


# --- the map -------------------------------------------------------------------------------


@dataclass
class StabilityData:
    rpms: np.ndarray
    tunnel_steps_s: np.ndarray
    tunnel_fraction: np.ndarray  # (rpm, dt)
    tunnel_limits: dict
    contacts: list
    contact_steps_s: np.ndarray
    rebounds: list  # one dict per contact
    chatter: dict  # {"guarded": ..., "unguarded": ...}
    flight: dict


def stability_data(quick: bool = False) -> StabilityData:
    """Everything the map shows. `quick` uses small grids (for tests)."""
    if quick:
        rpms = np.array([300.0, 1100.0])
        tunnel_steps = np.array([1e-4, 3e-3])
        contact_steps = np.array([1e-6, PAPER_DT_S])
        flight_steps = np.array([2e-3, 0.1])
        speeds = (20.0, 40.0)
    else:
        rpms = np.arange(200.0, 1201.0, 100.0)
        tunnel_steps = np.logspace(-5, -2, 19)
        contact_steps = np.logspace(-7, -3.5, 43)
        flight_steps = np.logspace(-3.3, math.log10(0.5), 15)
        speeds = (10.0, 20.0, 30.0, 40.0)
    contacts = table3_contacts()
    return StabilityData(
        rpms=rpms,
        tunnel_steps_s=tunnel_steps,
        tunnel_fraction=tunnelling_map(rpms, tunnel_steps, granules=8 if quick else 16),
        tunnel_limits=tunnelling_limits(rpms),
        contacts=contacts,
        contact_steps_s=contact_steps,
        rebounds=[rebound_over_steps(c, contact_steps, phases=8 if quick else 16) for c in contacts],
        chatter={"guarded": disc_friction_chatter(True), "unguarded": disc_friction_chatter(False)},
        flight=flight_step_errors(flight_steps, speeds_m_s=speeds),
    )


def stability_rows(data: StabilityData) -> list[dict]:
    """The map's data as long-format rows: panel, series, x_name, x, y_name, y."""
    rows = []

    def add(panel, series, x_name, x, y_name, y):
        rows.append({"panel": panel, "series": series, "x_name": x_name, "x": float(x),
                     "y_name": y_name, "y": float(y)})

    for i, rpm in enumerate(data.rpms):
        for j, dt in enumerate(data.tunnel_steps_s):
            add("a", f"{rpm:g} rpm", "dt_s", dt, "tunnelled_fraction", data.tunnel_fraction[i, j])
        for key, values in data.tunnel_limits.items():
            add("a", key, "rpm", rpm, "dt_s", values[i])
    for contact, rebound in zip(data.contacts, data.rebounds):
        for j, dt in enumerate(data.contact_steps_s):
            for key in ("mean", "min", "max", "energy_gain"):
                add("b", contact.label, "dt_s", dt, f"rebound_{key}" if key != "energy_gain" else key,
                    rebound[key][j])
        add("b", contact.label, "critical_step_s", contact.critical_s, "restitution", contact.restitution)
    for name, chatter in data.chatter.items():
        for k, step in enumerate(chatter["step"]):
            add("c", name, "step", step, "slip_tangential_m_s", chatter["slip_tangential"][k])
    for j, h in enumerate(data.flight["h_s"]):
        add("d", "rk4", "h_s", h, "max_landing_error_m", data.flight["rk4_error_m"][j])
    add("d", "adaptive", "h_s", float("nan"), "max_landing_error_m", data.flight["adaptive_error_m"])
    return rows


def first_failure(x: np.ndarray, y: np.ndarray, threshold: float) -> float:
    """Smallest x (x ascending) at which y exceeds threshold (nan if never)."""
    over = np.flatnonzero(np.asarray(y) > threshold)
    return float(np.asarray(x)[over[0]]) if over.size else float("nan")


def plot_stability_map(path, csv_path=None, quick: bool = False, data: Optional[StabilityData] = None) -> StabilityData:
    """Draw the four-panel stability map to `path` (PNG); write its data to `csv_path`
    (default: none). Returns the data."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    data = data if data is not None else stability_data(quick)
    fig = Figure(figsize=(14.0, 10.5), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    (ax_a, ax_b), (ax_c, ax_d) = fig.subplots(2, 2)

    # a: tunnelling map
    dts, rpms = data.tunnel_steps_s, data.rpms
    edges_dt = _log_edges(dts)
    edges_rpm = _lin_edges(rpms)
    mesh = ax_a.pcolormesh(edges_dt, edges_rpm, data.tunnel_fraction, cmap="Reds", vmin=0.0, vmax=1.0)
    fig.colorbar(mesh, ax=ax_a, label="fraction of granules the vane passes through")
    lim = data.tunnel_limits
    ax_a.plot(lim["guard_limit_s"], rpms, "k-", lw=2, label="guard limit (r + t/2)/(|ω| R), vane tip")
    ax_a.plot(lim["limit_at_radius_s"], rpms, "k--", lw=1.5, label="same formula at r = 0.1 m")
    ax_a.plot(lim["automatic_s"], rpms, color="#0072b2", lw=2, label="pymunk model's automatic step")
    ax_a.set_xscale("log")
    ax_a.set_xlabel("time step dt (s)")
    ax_a.set_ylabel("spinner speed (rpm)")
    ax_a.set_title("a. pymunk: vane tunnelling (granule at rest, r = 0.1 m)")
    ax_a.legend(loc="lower left", fontsize="small", framealpha=0.9)

    # b: spring-damper rebound ratio over dt
    colours = ["#0072b2", "#56b4e9", "#009e73", "#e69f00", "#d55e00", "#cc79a7", "#000000"]
    steps = data.contact_steps_s
    for contact, rebound, colour in zip(data.contacts, data.rebounds, colours):
        ax_b.plot(steps, rebound["mean"], color=colour, lw=1.6, label=contact.label)
        ax_b.fill_between(steps, rebound["min"], rebound["max"], color=colour, alpha=0.12, lw=0)
        ax_b.plot([contact.critical_s], [np.interp(math.log(contact.critical_s), np.log(steps), rebound["mean"])],
                  "o", color=colour, ms=7, mec="black")
        ax_b.plot([steps[0]], [contact.restitution], "<", color=colour, ms=6)
    ax_b.axvline(PAPER_DT_S, color="grey", ls="--", lw=1.5)
    ax_b.text(PAPER_DT_S * 1.08, 0.12, "paper's step\n5e-5 s", color="grey", fontsize="small")
    ax_b.axhline(1.0, color="black", ls=":", lw=1)
    ax_b.text(steps[0] * 1.3, 1.08, "rebound faster than impact (energy gained)", fontsize="small")
    ax_b.set_xscale("log")
    ax_b.set_yscale("log")
    ax_b.set_ylim(0.1, 100.0)
    ax_b.set_xlabel("time step dt (s)")
    ax_b.set_ylabel("rebound ratio v_out / v_in (band: entry phases)")
    ax_b.set_title("b. spring-damper: Table 3 stiffness, one impact (● critical step, ◀ e)")
    ax_b.legend(loc="upper left", fontsize="small", framealpha=0.9)

    # c: disc friction chatter
    for name, style in (("unguarded", dict(color="#d55e00", lw=1.2, marker=".", ms=4)),
                        ("guarded", dict(color="#0072b2", lw=2.0))):
        chatter = data.chatter[name]
        ax_c.plot(chatter["step"], 1e3 * chatter["slip_tangential"], label=f"{name}", **style)
    c = data.chatter["guarded"]
    half = 0.5e3 * float(c["coulomb_dv"])
    for y in (half, -half):
        ax_c.axhline(y, color="grey", ls=":", lw=1)
    ax_c.text(c["step"][-1], half, "± μ g dt / 2", ha="right", va="bottom", color="grey", fontsize="small")
    ax_c.set_ylim(-4 * half, 4 * half)
    start_slip = 1e3 * float(c["slip_tangential"][0])
    enter = int(np.argmax(1e3 * c["slip_tangential"] > -3.9 * half))
    ax_c.annotate(f"dropped at rest: slip {start_slip:.0f} mm/s at step 0,\ndragged up to the disc speed by μ g",
                  xy=(c["step"][enter], -3.9 * half), xytext=(c["step"][1], -2.6 * half), fontsize="small",
                  arrowprops=dict(arrowstyle="->", color="grey"))
    ax_c.text(c["step"][-1], 3.3 * half,
              f"guarded: tangential slip 0; radial drift ω² r dt = {1e3 * float(c['drift']):.2f} mm/s,\n"
              "constant (one step of centripetal motion), no sign change",
              ha="right", va="bottom", fontsize="small", color="#0072b2")
    ax_c.set_xlabel("step")
    ax_c.set_ylabel("slip relative to the disc, along rotation (mm/s)")
    ax_c.set_title(f"c. disc friction: granule dropped on a 40 rpm disc, dt = {float(c['dt_s']) * 1e3:.2f} ms")
    ax_c.legend(loc="upper left", fontsize="small")

    # d: flight landing error
    fl = data.flight
    ax_d.plot(fl["h_s"], 1e3 * fl["rk4_error_m"], "o-", color="#0072b2", label="fixed-step RK4")
    ax_d.axhline(1.0, color="#d55e00", ls="--", lw=1.2, label="1 mm")
    ax_d.axhline(0.1, color="grey", ls=":", lw=1.2, label="0.1 mm")
    ax_d.axhline(1e3 * float(fl["adaptive_error_m"]), color="#009e73", lw=2, label="default adaptive DP5(4)")
    ax_d.axvline(float(fl["rk4_stability_limit_s"]), color="black", ls="-.", lw=1,
                 label="RK4 linear stability limit (40 m/s)")
    ax_d.set_xscale("log")
    ax_d.set_yscale("log")
    ax_d.set_xlabel("RK4 step h (s)")
    ax_d.set_ylabel("largest landing-point error (mm)")
    ax_d.set_title("d. flight: landing error against the DOP853 reference")
    ax_d.legend(loc="upper left", fontsize="small")

    fig.suptitle("Where the numerical methods fail (spreadgym stability map)", fontsize="large")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    if csv_path is not None:
        write_rows(stability_rows(data), csv_path)
    return data


def write_rows(rows: list[dict], path) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=["panel", "series", "x_name", "x", "y_name", "y"])
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})


def _log_edges(x: np.ndarray) -> np.ndarray:
    lx = np.log10(x)
    mid = 0.5 * (lx[1:] + lx[:-1])
    return 10 ** np.concatenate([[lx[0] - (mid[0] - lx[0])], mid, [lx[-1] + (lx[-1] - mid[-1])]])


def _lin_edges(x: np.ndarray) -> np.ndarray:
    mid = 0.5 * (x[1:] + x[:-1])
    return np.concatenate([[x[0] - (mid[0] - x[0])], mid, [x[-1] + (x[-1] - mid[-1])]])
