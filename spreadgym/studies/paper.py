"""The seed paper's simulation study, rerun with spreadgym's spinner model.

The paper simulated one compound 10-16-10 granule released 43 mm from the axis and
50 mm above a four-vane spinner, and reported the departure (translational) velocity
and the granule's rotational velocity for
  * the spinner material (MC, PVC, steel) at 300 mm and 500 rpm (its Figs. 6 and 7),
  * the disc speed (200, 500, 800, 1100 rpm), MC, 300 mm (Fig. 8),
  * the disc diameter (200, 300, 400 mm), MC, 500 rpm (Fig. 9).
`paper_study` runs those cases on the `paper` scene with every granule released from
the one point (`feed.spread_m = 0`), at random spinner phases, once with granules
free to turn about the vertical axis (they can roll along a vane face) and once
with rotation locked (the point mass of the classic sliding models). Vanes run from
25 mm to the rim for every diameter. The material sets both the disc and the vanes:
friction (paper Table 2) and restitution (Table 3) come from the material library.

Each row also carries a closed-form reference (`closed_form_*`): a granule of the
median size that starts at rest on the leading face of a radial vane at the release
radius and moves out under `spreadgym.physics.analytic.vane_slide.run_along_vane` (slide for
a locked granule; slide, then roll for a free one), with disc friction, but without
the drop, the bounces and the catch.

`plot_paper_study` draws the counterparts of the paper's Figs. 6-9 (and the
departure direction), `write_study` the CSV. Both are what `spreadgym study paper`
writes into docs/study/.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Optional, Sequence

import numpy as np

from spreadgym.config.materials import load_library
from spreadgym.config.scene import RPM_TO_RAD_S, Scene, load_scene
from spreadgym.errors import SpreadgymError
from spreadgym.physics.analytic.motions import Face
from spreadgym.physics.analytic.vane_slide import CatchState, FaceFriction, VaneOptions, run_along_vane
from spreadgym.physics.contacts import resolve_contacts
from spreadgym.physics.departure import Departure
from spreadgym.physics.granules import sample_granules
from spreadgym.physics.selection import choose_model

SCENE = "paper"
ROTATIONS = ("free", "locked")
SWEEPS = ("material", "rpm", "diameter")
MATERIALS = ("mc", "pvc", "steel")
RPMS = (200.0, 500.0, 800.0, 1100.0)
DIAMETERS_M = (0.2, 0.3, 0.4)
BASE_MATERIAL, BASE_RPM, BASE_DIAMETER_M = "mc", 500.0, 0.3
CSV_NAME = "paper-study.csv"
FIGURES = ("fig6-speed-by-material.png", "fig7-spin-by-material.png", "fig8-speed-vs-rpm.png",
           "fig9-speed-vs-diameter.png", "departure-angle.png")


@dataclass(frozen=True)
class Case:
    """One spinner set-up of the study (run once per rotation mode)."""

    sweep: str  # "material", "rpm" or "diameter": the figure it belongs to
    material: str
    rpm: float
    diameter_m: float

    def overrides(self, granules: int, rotation: str, seed: int = 0) -> dict:
        """Dotted-key overrides of the `paper` scene for this case."""
        return {
            "spinner.material": self.material,
            "spinner.rpm": self.rpm,
            "spinner.radius_m": 0.5 * self.diameter_m,
            "vanes.outer_radius_m": None,  # vanes span to the rim
            "feed.spread_m": 0.0,  # the paper's single release point
            "granule.rotation": rotation,
            "sim.granules": granules,
            "sim.seed": seed,
        }


def paper_cases() -> list[Case]:
    """The paper's cases, in the order of its figures (the base case appears in every sweep)."""
    cases = [Case("material", m, BASE_RPM, BASE_DIAMETER_M) for m in MATERIALS]
    cases += [Case("rpm", BASE_MATERIAL, rpm, BASE_DIAMETER_M) for rpm in RPMS]
    cases += [Case("diameter", BASE_MATERIAL, BASE_RPM, d) for d in DIAMETERS_M]
    return cases


def study_scene(case: Case, granules: int, rotation: str, seed: int = 0) -> Scene:
    """The validated `paper` scene of one case."""
    return load_scene(SCENE, case.overrides(granules, rotation, seed))


def paper_study(
    granules: int = 200,
    model: str = "pymunk",
    progress: Optional[Callable[[int, int], None]] = None,
    cases: Optional[Iterable[Case]] = None,
    rotations: Sequence[str] = ROTATIONS,
    seed: int = 0,
) -> list[dict]:
    """One row per (case, rotation), cases in order and rotations side by side.

    Every run samples its granules with the same seed, so all cases see the same
    spinner phases and granule sizes (common random numbers: differences between
    cases are not sampling noise). A set-up shared by several sweeps is simulated
    once. `progress(done, total)` is called after every row.
    """
    if isinstance(granules, bool) or not isinstance(granules, (int, np.integer)) or granules < 1:
        raise SpreadgymError(f"granules: {granules!r} must be a whole number of at least 1")
    for rotation in rotations:
        if rotation not in ROTATIONS:
            raise SpreadgymError(f"rotation: {rotation!r} is not one of {', '.join(ROTATIONS)}")
    cases = paper_cases() if cases is None else list(cases)
    library = load_library()
    total = len(cases) * len(rotations)
    done_runs: dict[tuple, dict] = {}
    rows = []
    for case in cases:
        for rotation in rotations:
            key = (case.material, case.rpm, case.diameter_m, rotation)
            if key not in done_runs:
                done_runs[key] = _run_case(case, int(granules), rotation, model, seed, library)
            rows.append({"sweep": case.sweep, **done_runs[key]})
            if progress is not None:
                progress(len(rows), total)
    return rows


def _run_case(case: Case, granules: int, rotation: str, model: str, seed: int, library) -> dict:
    from spreadgym.spread.pipeline import run_spinner  # the pipeline pulls in the flight model

    scene = study_scene(case, granules, rotation, seed)
    contacts = resolve_contacts(scene, library)
    chosen, _ = choose_model(scene, model)
    fertilizer = library.fertilizer_of(scene)
    batch = sample_granules(scene, fertilizer)
    departure = run_spinner(scene, batch, contacts, chosen)
    stats = departure_statistics(departure, scene.spinner.omega_rad_s)
    ref = closed_form_departure(
        rpm=case.rpm, disc_radius_m=scene.spinner.radius_m, rotation=rotation,
        vane_friction=contacts.vane_friction, disc_friction=contacts.disc_friction,
        granule_radius_m=0.5 * fertilizer.size.d50_m, release_radius_m=scene.feed.radius_m,
        inner_radius_m=scene.vanes.inner_radii_m()[0], half_thickness_m=0.5 * scene.vanes.thickness_m,
    )
    return {
        "material": case.material,
        "rpm": case.rpm,
        "diameter_m": case.diameter_m,
        "rotation": rotation,
        "model": chosen,
        "granules": granules,
        **stats,
        "rim_speed_m_s": abs(scene.spinner.omega_rad_s) * scene.spinner.radius_m,
        "closed_form_speed_m_s": float(ref["speed_m_s"][0]),
        "closed_form_angle_deg": float(ref["angle_deg"][0]),
        "closed_form_spin_rad_s": float(ref["spin_rad_s"][0]),
        "vane_friction": contacts.vane_friction,
        "disc_friction": contacts.disc_friction,
        "vane_restitution": contacts.vane_restitution,
        "dt_s": departure.dt_s,
    }


def departure_statistics(departure: Departure, omega_rad_s: float) -> dict:
    """Means and spreads over the departed granules.

    Angle: from the disc's tangent at the departure point (direction of rotation)
    towards the outward radial, as in `pipeline.departure_summary`; the radial and
    tangential components are those of the velocity in the same axes. Spin: about the
    vertical axis in the machine frame, ccw positive (a disc turning ccw at 500 rpm
    turns at +52 rad/s).
    """
    gone = departure.departed
    n = int(gone.sum())
    out = {"departed": n}
    if n == 0:
        nothing = ("speed_mean_m_s", "speed_std_m_s", "speed_sem_percent", "spin_mean_rad_s", "spin_std_rad_s",
                   "angle_mean_deg", "angle_std_deg", "radial_mean_m_s", "tangential_mean_m_s",
                   "time_on_spinner_mean_s")
        return {**out, **{k: 0.0 for k in nothing}}
    radial, tangential = departure.radial_tangential_m_s(omega_rad_s)
    angle = np.degrees(np.arctan2(radial, tangential))
    speed = departure.speed_m_s[gone]
    spin = departure.spin_rad_s[gone]

    def sd(a):
        return float(a.std(ddof=1)) if a.size > 1 else 0.0

    mean_speed = float(speed.mean())
    return {
        **out,
        "speed_mean_m_s": mean_speed,
        "speed_std_m_s": sd(speed),
        "speed_sem_percent": 100.0 * sd(speed) / math.sqrt(n) / mean_speed if mean_speed > 0 else 0.0,
        "spin_mean_rad_s": float(spin.mean()),
        "spin_std_rad_s": sd(spin),
        "angle_mean_deg": float(angle.mean()),
        "angle_std_deg": sd(angle),
        "radial_mean_m_s": float(radial.mean()),
        "tangential_mean_m_s": float(tangential.mean()),
        "time_on_spinner_mean_s": float(departure.time_s[gone].mean()),
    }


def closed_form_departure(
    rpm,
    disc_radius_m,
    rotation: str,
    vane_friction: float,
    disc_friction: float,
    granule_radius_m: float = 0.0015,
    release_radius_m: float = 0.043,
    inner_radius_m: float = 0.025,
    half_thickness_m: float = 0.0025,
) -> dict:
    """Departure of a granule that starts at rest on a radial vane's leading face.

    Exact closed forms of `vane_slide.run_along_vane` (no drop, no bounce, no catch):
    sliding for rotation "locked", sliding then rolling without slip for "free".
    `rpm` and `disc_radius_m` broadcast (arrays give curves). Returns arrays:
    speed_m_s, angle_deg (from the tangent), spin_rad_s (machine frame), time_s.
    """
    rpm, radius = np.broadcast_arrays(np.atleast_1d(np.asarray(rpm, dtype=float)),
                                      np.atleast_1d(np.asarray(disc_radius_m, dtype=float)))
    omega = rpm * RPM_TO_RAD_S
    w = half_thickness_m + granule_radius_m
    x0 = math.sqrt(max(release_radius_m**2 - w * w, inner_radius_m**2))
    x_tip = radius  # radial vane to the rim: the centre line reaches the rim first
    run = run_along_vane(Face(omega, w, inner_radius_m, x_tip, radius), CatchState(x0, 0.0, granule_radius_m),
                         FaceFriction(vane_friction, disc_friction), VaneOptions(rotation=rotation))
    speed = np.hypot(run.vel_u, run.vel_n)
    r = np.hypot(run.pos_u, run.pos_n)
    radial = (run.vel_u * run.pos_u + run.vel_n * run.pos_n) / r
    tangential = (run.vel_n * run.pos_u - run.vel_u * run.pos_n) / r
    spin = np.zeros_like(speed) if rotation == "locked" else omega + run.spin_offset / granule_radius_m
    ok = run.outcome == 0
    nan = np.full_like(speed, np.nan)
    return {
        "speed_m_s": np.where(ok, speed, nan),
        "angle_deg": np.where(ok, np.degrees(np.arctan2(radial, tangential)), nan),
        "spin_rad_s": np.where(ok, spin, nan),
        "time_s": np.where(ok, run.t_s, nan),
    }


# --- output ------------------------------------------------------------------------------


def write_study(rows: list[dict], out_dir) -> Path:
    """Write the rows as CSV (out_dir/paper-study.csv); returns the path."""
    if not rows:
        raise SpreadgymError("study: no rows to write")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / CSV_NAME
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _csv_value(v) for k, v in row.items()})
    return path


def _csv_value(value):
    if isinstance(value, float):
        return f"{value:.6g}"
    return value


FREE_COLOUR, LOCKED_COLOUR, REF_COLOUR, RIM_COLOUR = "#0072b2", "#d55e00", "#333333", "#999999"
STYLE = {"free": (FREE_COLOUR, "o", "free to turn (rolls along the vane)"),
         "locked": (LOCKED_COLOUR, "s", "rotation locked (slides)")}
MATERIAL_LABEL = {"mc": "MC", "pvc": "PVC", "steel": "steel"}


def _figure(figsize=(7.5, 5.4)):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _pick(rows, sweep, rotation):
    return [r for r in rows if r["sweep"] == sweep and r["rotation"] == rotation]


def _material_label(row) -> str:
    name = MATERIAL_LABEL.get(row["material"], row["material"])
    return f"{name}\nμ {row['vane_friction']:.2f}, e {row['vane_restitution']:.3g}"


def _subtitle(rows, sweep) -> str:
    r = next(r for r in rows if r["sweep"] == sweep)
    fixed = {"material": f"{r['diameter_m'] * 1e3:.0f} mm disc, {r['rpm']:.0f} rpm",
             "rpm": f"{MATERIAL_LABEL.get(r['material'], r['material'])}, {r['diameter_m'] * 1e3:.0f} mm disc",
             "diameter": f"{MATERIAL_LABEL.get(r['material'], r['material'])}, {r['rpm']:.0f} rpm"}[sweep]
    return (f"{fixed}, release 43 mm from the axis, 50 mm drop\n"
            f"mean of {r['granules']} granules, error bars ±1 s.d. over granules")


def plot_paper_study(rows: list[dict], out_dir) -> list[Path]:
    """PNGs mirroring the paper's Figs. 6-9, plus the departure direction; returns the paths.

    A figure is drawn only when its sweep is in `rows`.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sweeps = {r["sweep"] for r in rows}
    written = []
    if "material" in sweeps:
        written.append(_plot_material_speed(rows, out / "fig6-speed-by-material.png"))
        written.append(_plot_material_spin(rows, out / "fig7-spin-by-material.png"))
    if "rpm" in sweeps:
        written.append(_plot_sweep(rows, "rpm", out / "fig8-speed-vs-rpm.png"))
    if "diameter" in sweeps:
        written.append(_plot_sweep(rows, "diameter", out / "fig9-speed-vs-diameter.png"))
    if sweeps:
        written.append(_plot_angles(rows, out / "departure-angle.png"))
    return written


def _bars(ax, rows, value, error, ref=None, rotations=ROTATIONS):
    """Grouped bars, one per rotation mode side by side for each material."""
    width = 0.76 / len(rotations) if len(rotations) > 1 else 0.5
    materials = list(dict.fromkeys(r["material"] for r in rows if r["sweep"] == "material"))
    x = np.arange(len(materials))
    for k, rotation in enumerate(rotations):
        picked = {r["material"]: r for r in _pick(rows, "material", rotation)}
        if not picked:
            continue
        colour, _, label = STYLE[rotation]
        xs = x + (k - 0.5 * (len(rotations) - 1)) * width
        vals = [value(picked[m]) for m in materials]
        errs = [error(picked[m]) for m in materials]
        bars = ax.bar(xs, vals, width, yerr=errs, capsize=4, color=colour, alpha=0.85, label=label)
        ax.bar_label(bars, fmt="%.2f" if max(abs(v) for v in vals) < 100 else "%.0f", label_type="center",
                     color="white", fontweight="bold")
        if ref is not None:
            refs = [ref(picked[m]) for m in materials]
            ax.hlines(refs, xs - 0.45 * width, xs + 0.45 * width, colors=REF_COLOUR, linestyles="--", lw=1.6,
                      label="closed form, from rest on the vane" if k == 0 else None)
    labels = {r["material"]: _material_label(r) for r in rows if r["sweep"] == "material"}
    ax.set_xticks(x, [labels[m] for m in materials])
    return materials


def _plot_material_speed(rows, path) -> Path:
    fig = _figure()
    ax = fig.add_subplot()
    _bars(ax, rows, lambda r: r["speed_mean_m_s"], lambda r: r["speed_std_m_s"],
          ref=lambda r: r["closed_form_speed_m_s"])
    top = max(r["speed_mean_m_s"] + r["speed_std_m_s"] for r in rows if r["sweep"] == "material")
    ax.set_ylim(0, 1.08 * top)
    ax.set_ylabel("departure speed (m/s)")
    ax.set_xlabel("spinner material (vane/disc friction μ, vane restitution e)")
    ax.set_title("Translational velocity at departure by spinner material (cf. paper Fig. 6)\n"
                 + _subtitle(rows, "material"), fontsize="medium")
    fig.legend(loc="outside lower center", ncol=3, fontsize="small", frameon=False)
    ax.grid(True, axis="y", alpha=0.3)
    fig.savefig(path)
    return path


def _plot_material_spin(rows, path) -> Path:
    fig = _figure()
    ax = fig.add_subplot()
    _bars(ax, rows, lambda r: -r["spin_mean_rad_s"], lambda r: r["spin_std_rad_s"],
          ref=lambda r: -r["closed_form_spin_rad_s"], rotations=("free",))
    top = max(-r["spin_mean_rad_s"] + r["spin_std_rad_s"] for r in rows if r["sweep"] == "material")
    ax.set_ylim(0, 1.08 * max(top, 1.0))
    ax.set_ylabel("granule spin at departure (rad/s, clockwise)")
    ax.set_xlabel("spinner material (vane/disc friction μ, vane restitution e)")
    ax.set_title("Rotational velocity at departure by spinner material (cf. paper Fig. 7)\n"
                 + _subtitle(rows, "material")
                 + "\nspin about the vertical axis; the disc turns counter-clockwise; locked granules: 0",
                 fontsize="medium")
    secondary = ax.secondary_yaxis("right", functions=(lambda w: w / RPM_TO_RAD_S, lambda n: n * RPM_TO_RAD_S))
    secondary.set_ylabel("granule spin (rpm)")
    fig.legend(loc="outside lower center", ncol=3, fontsize="small", frameon=False)
    ax.grid(True, axis="y", alpha=0.3)
    fig.savefig(path)
    return path


def _plot_sweep(rows, sweep, path) -> Path:
    """Speed against rpm or diameter: free and locked lines, closed forms, rim speed."""
    key, scale, xlabel, fig_no = {
        "rpm": ("rpm", 1.0, "spinner speed (rpm)", 8),
        "diameter": ("diameter_m", 1e3, "spinner diameter (mm)", 9),
    }[sweep]
    fig = _figure()
    ax = fig.add_subplot()
    any_row = next(r for r in rows if r["sweep"] == sweep)
    xs_all = sorted({r[key] for r in rows if r["sweep"] == sweep})
    lo, hi = xs_all[0], xs_all[-1]
    pad = 0.08 * (hi - lo) if hi > lo else 0.1 * hi
    grid = np.linspace(max(lo - pad, 1e-6), hi + pad, 120)
    base = load_scene(SCENE)
    fertilizer = load_library().fertilizer_of(base)
    for rotation in ROTATIONS:
        picked = sorted(_pick(rows, sweep, rotation), key=lambda r: r[key])
        if not picked:
            continue
        colour, marker, label = STYLE[rotation]
        x = np.array([r[key] for r in picked]) * scale
        y = np.array([r["speed_mean_m_s"] for r in picked])
        e = np.array([r["speed_std_m_s"] for r in picked])
        ax.errorbar(x, y, yerr=e, color=colour, marker=marker, ms=6, capsize=3, lw=1.8, label=label)
        rpm = grid if sweep == "rpm" else any_row["rpm"]
        radius = 0.5 * (grid if sweep == "diameter" else any_row["diameter_m"])
        ref = closed_form_departure(rpm, radius, rotation, picked[0]["vane_friction"], picked[0]["disc_friction"],
                                    granule_radius_m=0.5 * fertilizer.size.d50_m,
                                    release_radius_m=base.feed.radius_m, inner_radius_m=base.vanes.inner_radii_m()[0],
                                    half_thickness_m=0.5 * base.vanes.thickness_m)
        ax.plot(grid * scale, ref["speed_m_s"], "--", color=colour, lw=1.1, alpha=0.9,
                label=f"closed form, {'slide' if rotation == 'locked' else 'slide then roll'} from rest")
        for xi, yi in zip(x, y):
            ax.annotate(f"{yi:.2f}", (xi, yi), textcoords="offset points",
                        xytext=(-8, 8) if rotation == "free" else (8, -14),
                        ha="right" if rotation == "free" else "left", fontsize="small", color=colour)
    rim_rpm = grid if sweep == "rpm" else any_row["rpm"]
    rim_radius = 0.5 * (grid if sweep == "diameter" else any_row["diameter_m"])
    ax.plot(grid * scale, rim_rpm * RPM_TO_RAD_S * rim_radius, ":", color=RIM_COLOUR, lw=1.2,
            label="rim speed ΩR")
    ax.set_xlim(grid[0] * scale, grid[-1] * scale)
    ax.set_ylim(bottom=0)
    ax.set_xticks(np.array(xs_all) * scale)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("departure speed (m/s)")
    ax.set_title(f"Translational velocity at departure against {xlabel.split(' (')[0]} "
                 f"(cf. paper Fig. {fig_no})\n" + _subtitle(rows, sweep), fontsize="medium")
    handles, labels = ax.get_legend_handles_labels()
    order = sorted(range(len(labels)), key=lambda i: (labels[i].startswith("closed"), labels[i].startswith("rim")))
    ax.legend([handles[i] for i in order], [labels[i] for i in order], loc="upper left", fontsize="small",
              frameon=False)
    ax.grid(True, alpha=0.3)
    fig.savefig(path)
    return path


def _plot_angles(rows, path) -> Path:
    """Departure angle from the tangent, free against locked, for every sweep."""
    sweeps = [s for s in SWEEPS if any(r["sweep"] == s for r in rows)]
    fig = _figure(figsize=(3.2 * len(sweeps) + 1.0, 4.2))
    axes = fig.subplots(1, len(sweeps), sharey=True, squeeze=False)[0]
    for ax, sweep in zip(axes, sweeps):
        for k, rotation in enumerate(ROTATIONS):
            picked = _pick(rows, sweep, rotation)
            if sweep != "material":
                key = "rpm" if sweep == "rpm" else "diameter_m"
                picked = sorted(picked, key=lambda r: r[key])
            if not picked:
                continue
            colour, marker, label = STYLE[rotation]
            if sweep == "material":
                x = np.arange(len(picked)) + (k - 0.5) * 0.2
                labels = [MATERIAL_LABEL.get(r["material"], r["material"]) for r in picked]
                ax.set_xticks(np.arange(len(picked)), labels)
                ax.set_xlim(-0.6, len(picked) - 0.4)
                ax.set_xlabel("spinner material")
            elif sweep == "rpm":
                x = np.array([r["rpm"] for r in picked])
                ax.set_xticks(x)
                ax.set_xlabel("spinner speed (rpm)")
            else:
                x = np.array([r["diameter_m"] for r in picked]) * 1e3
                ax.set_xticks(x)
                ax.set_xlabel("spinner diameter (mm)")
            y = [r["angle_mean_deg"] for r in picked]
            ax.errorbar(x, y, yerr=[r["angle_std_deg"] for r in picked], color=colour, marker=marker,
                        ls="-" if sweep != "material" else "none", capsize=3, label=label)
            ax.plot(x, [r["closed_form_angle_deg"] for r in picked], ls="none", marker="_", ms=14, mew=2,
                    color=REF_COLOUR, label="closed form, from rest" if k == 0 else None)
        ax.grid(True, alpha=0.3)
        ax.set_title({"material": "by material (300 mm, 500 rpm)", "rpm": "against speed (MC, 300 mm)",
                      "diameter": "against diameter (MC, 500 rpm)"}[sweep], fontsize="medium")
    axes[0].set_ylabel("departure angle from the tangent (deg)")
    lo = min(min(r["angle_mean_deg"] - r["angle_std_deg"], r["closed_form_angle_deg"]) for r in rows)
    hi = max(max(r["angle_mean_deg"] + r["angle_std_deg"], r["closed_form_angle_deg"]) for r in rows)
    axes[0].set_ylim(math.floor(lo / 5) * 5 - 5, math.ceil(hi / 5) * 5 + 5)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize="small", frameon=False)
    fig.suptitle("Direction of departure: 0° = along the rim (tangent), 90° = straight out", fontsize="medium")
    fig.savefig(path)
    return path
