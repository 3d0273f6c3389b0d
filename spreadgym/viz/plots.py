"""Pictures of one simulation: plan view of the spinner, landing points, tray pattern, CV curve.

Everything draws on explicit `matplotlib.figure.Figure` objects with an Agg canvas:
no pyplot, no global backend switch, so it works headless and in worker processes.

Frame (as everywhere in spreadgym): x across the track, to the right of the machine;
y forward, the driving direction; metres. The transverse pattern is across x.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, FancyArrowPatch

from spreadgym.physics.geometry import vane_segments, zone_radius_m
from spreadgym.spread import pattern

FIGSIZE_IN = (7.0, 5.0)
DPI = 100
RAY_BEYOND_DISC_M = 0.3  # departure rays reach this far beyond the disc ...
RAY_BEYOND_ZONE_M = 0.15  # ... or this far beyond the deflector zone, whichever is further

# Colours (colour-blind friendly, from the Okabe-Ito palette where it matters).
DISC_FACE, DISC_EDGE = "#eef1f4", "#59636e"
VANE = "#9aa6b2"
PLATE = "#1f2328"
TRACK = "#d55e00"
RAY = "#e69f00"
BAR = "#9ecae1"
LINE = "#08519c"
TARGET = "#444444"
THRESHOLD = "#c0392b"
EFFECTIVE = "#009e73"


def _new_figure(figsize=FIGSIZE_IN, dpi=DPI, **kwargs) -> Figure:
    fig = Figure(figsize=figsize, dpi=dpi, layout="constrained", **kwargs)
    FigureCanvasAgg(fig)
    return fig


def _forward_arrow(ax, x=0.06, y0=0.76, y1=0.95) -> None:
    """An arrow in axes coordinates pointing +y, labelled 'forward'."""
    ax.annotate("", xy=(x, y1), xytext=(x, y0), xycoords="axes fraction",
                arrowprops=dict(arrowstyle="-|>", color="black", lw=1.5, mutation_scale=14))
    ax.text(x + 0.02, 0.5 * (y0 + y1), "forward", transform=ax.transAxes, rotation=90,
            va="center", ha="left", fontsize="small")


def _side_legend(ax, handles) -> None:
    """Legend to the right of the axes (the figure must leave room there, as
    `write_simulation_plots` does)."""
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.03, 1.0), borderaxespad=0.0,
              fontsize="small", frameon=False)


def _note(ax, text: str) -> None:
    """A message over the plot, e.g. when there is nothing to draw."""
    ax.text(0.5, 0.62, text, transform=ax.transAxes, ha="center", va="center", zorder=10,
            bbox=dict(boxstyle="round,pad=0.4", facecolor="white", edgecolor="#bbbbbb"))


def _time_to_circle(position: np.ndarray, velocity: np.ndarray, radius: float) -> np.ndarray:
    """t >= 0 (N,) at which p + t v reaches |x| = radius going outwards (0 if it does not move)."""
    a = np.sum(velocity * velocity, axis=1)
    b = 2.0 * np.sum(position * velocity, axis=1)
    c = np.sum(position * position, axis=1) - radius * radius
    root = (-b + np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))) / np.maximum(2.0 * a, 1e-300)
    return np.where(a > 0, np.maximum(root, 0.0), 0.0)


def _first_plate_hit(p: np.ndarray, v: np.ndarray, plates) -> Optional[tuple[float, np.ndarray]]:
    """(t, point) of the first crossing of the ray p + t v (t > 0) with a plate's centre line."""
    best = None
    for plate in plates:
        a, b = (np.asarray(e, dtype=float) for e in plate.endpoints())
        d = b - a
        den = v[0] * (-d[1]) - v[1] * (-d[0])
        if abs(den) < 1e-15:
            continue
        rhs = a - p
        t = (rhs[0] * (-d[1]) - rhs[1] * (-d[0])) / den
        s = (v[0] * rhs[1] - v[1] * rhs[0]) / den
        if t > 1e-12 and 0.0 <= s <= 1.0 and (best is None or t < best[0]):
            best = (t, p + t * v)
    return best


def _deflector_zone_m(result) -> float:
    plates = result.scene.deflectors
    if not plates:
        return 0.0
    return zone_radius_m(plates, float(result.granules.radius_m.max()))


def _view_radius_m(result) -> float:
    """Where the departure rays end: a few dm beyond the disc and beyond the deflector zone."""
    radius = result.scene.spinner.radius_m + RAY_BEYOND_DISC_M
    zone = _deflector_zone_m(result)
    return max(radius, zone + RAY_BEYOND_ZONE_M) if zone else radius


def _ray_indices(result, max_rays: int, first: int) -> np.ndarray:
    """The tracked granules (the first `first`) that departed, then evenly spread others."""
    departed = np.flatnonzero(result.launch.departed)
    head = departed[departed < first]
    rest = departed[departed >= first]
    room = max(0, max_rays - head.size)
    if rest.size > room:
        rest = rest[np.unique(np.linspace(0, rest.size - 1, room).round().astype(int))] if room else rest[:0]
    return np.concatenate([head, rest])


def first_disc(result) -> tuple[np.ndarray, int, int]:
    """The plan view's disc (a twin machine's first): its axis in the machine frame (m), and how many of the
    departure's granules and paths are its own (every disc throws as many; the first disc's come first)."""
    centres = result.scene.disc_centres_m
    return (np.asarray(centres[0], dtype=float), len(result.departure.position_m) // len(centres),
            len(result.departure.tracks) // len(centres))


def departure_rays(result, indices: Sequence[int], reach_m: float,
                   centre: Sequence[float] = (0.0, 0.0)) -> list[np.ndarray]:
    """Straight plan-view paths (K, 2) from the disc edge out to radius `reach_m` about `centre` (the disc's
    axis in the machine frame), in the frame of that disc.

    Without plates: along the departure velocity. With plates: to the first plate the
    departure line meets (if the granule was turned), then to where the granule left
    the deflector zone, then along its launch velocity (one-bounce reconstruction)."""
    dep, launch, plates = result.departure, result.launch, result.scene.deflectors
    centre = np.asarray(centre, dtype=float)
    paths = []
    for i in indices:
        p0, v0 = dep.position_m[i], dep.velocity_m_s[i]
        p1, v1 = launch.position_m[i], launch.velocity_m_s[i]
        points = [p0]
        if plates and launch is not dep:
            turned = np.hypot(*(v1 - v0)) > 1e-3 * max(np.hypot(*v0), 1e-9)
            hit = _first_plate_hit(p0, v0, plates) if turned else None
            if hit is not None:
                points.append(hit[1])
            points.append(p1)
        start = points[-1]
        t = _time_to_circle((start - centre)[None, :], v1[None, :], reach_m)[0]
        if t > 0:
            points.append(start + t * v1)
        paths.append(np.asarray(points) - centre)
    return paths


def plan_view(ax, result, max_tracks: int = 30, max_rays: int = 80, legend: bool = True) -> None:
    """Disc, vanes (at spinner angle 0), deflector plates, granule paths over the disc and
    straight departure rays, in the machine frame (metres, equal aspect)."""
    scene = result.scene
    radius = scene.spinner.radius_m
    reach = _view_radius_m(result)
    handles = []

    ax.add_patch(Circle((0, 0), radius, facecolor=DISC_FACE, edgecolor=DISC_EDGE, lw=1.2, zorder=1))
    handles.append(Line2D([], [], marker="o", ls="none", ms=10, mfc=DISC_FACE, mec=DISC_EDGE,
                          label=f"disc (R = {1e3 * radius:.0f} mm)"))

    inner, outer = vane_segments(scene)
    for a, b in zip(inner, outer):
        ax.plot([a[0], b[0]], [a[1], b[1]], color=VANE, lw=3, solid_capstyle="butt", zorder=2)
    handles.append(Line2D([], [], color=VANE, lw=3, label="vanes (at angle 0)"))

    # Sense of rotation: a curved arrow just outside the disc.
    sense = 1.0 if scene.spinner.omega_rad_s > 0 else -1.0
    a0, a1 = math.radians(35), math.radians(35 + sense * 50)
    r_arc = 1.12 * radius
    ax.add_patch(FancyArrowPatch(
        (r_arc * math.cos(a0), r_arc * math.sin(a0)), (r_arc * math.cos(a1), r_arc * math.sin(a1)),
        connectionstyle=f"arc3,rad={0.22 * sense}", arrowstyle="-|>", mutation_scale=10,
        color=DISC_EDGE, lw=1.2, zorder=3))

    feed = scene.feed
    fx, fy = feed.radius_m * math.cos(feed.angle_rad), feed.radius_m * math.sin(feed.angle_rad)
    ax.plot([fx], [fy], marker="v", color="black", ms=7, ls="none", zorder=6)
    handles.append(Line2D([], [], marker="v", color="black", ls="none", ms=7, label="feed point"))

    centre, own, own_tracks = first_disc(result)  # a twin machine: its first disc, in that disc's frame
    tracks = [np.asarray(t) - centre for t in result.departure.tracks[:min(max_tracks, own_tracks)]]
    indices = _ray_indices(result, max_rays, len(tracks))
    rays = departure_rays(result, indices[indices < own], reach, centre)
    for path in rays:
        ax.plot(path[:, 0], path[:, 1], color=RAY, lw=0.8, alpha=0.55, zorder=3)
    if rays:
        handles.append(Line2D([], [], color=RAY, lw=1.2, label="flight direction"))
    for path in tracks:
        ax.plot(path[:, 0], path[:, 1], color=TRACK, lw=1.0, zorder=4)
    if tracks:
        handles.append(Line2D([], [], color=TRACK, lw=1.2, label="path on the disc"))

    kept = ~result.departure.departed[:own]
    if kept.any():
        pos = result.departure.position_m[:own][kept] - centre
        ax.plot(pos[:, 0], pos[:, 1], "x", color="black", ms=4, zorder=5)
        handles.append(Line2D([], [], marker="x", color="black", ls="none",
                              label=f"retained ({int(kept.sum())})"))

    for plate in scene.deflectors:
        (xa, ya), (xb, yb) = np.asarray(plate.endpoints()) - centre
        ax.plot([xa, xb], [ya, yb], color=PLATE, lw=4.5, solid_capstyle="round", zorder=7)
    if scene.deflectors:
        handles.append(Line2D([], [], color=PLATE, lw=4.5, label="deflector plate"))

    lim = 1.06 * reach
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.set_xlabel("x, across (m)")
    ax.set_ylabel("y, forward (m)")
    ax.grid(True, color="#e5e5e5", lw=0.6, zorder=0)
    ax.set_axisbelow(True)
    rot = "ccw" if sense > 0 else "cw"
    extra = f", {len(scene.deflectors)} deflector{'s' if len(scene.deflectors) != 1 else ''}" \
        if scene.deflectors else ""
    ax.set_title(f"Plan view: {scene.vanes.count} vanes, {scene.spinner.rpm:g} rpm {rot}{extra}")
    _forward_arrow(ax)
    if legend:
        _side_legend(ax, handles)


def landing_scatter(ax, result, max_points: int = 3000, colorbar: bool = True) -> None:
    """Landing points on the ground (x across, y along), spinner at the origin, target
    bout edges (+-W/2) dashed."""
    pos = result.landing.position_m
    diameter_mm = 1e3 * result.granules.diameter_m[result.landed]
    if pos.shape[0] > max_points:
        pick = np.unique(np.linspace(0, pos.shape[0] - 1, max_points).round().astype(int))
        pos, diameter_mm = pos[pick], diameter_mm[pick]
    half = 0.5 * result.scene.pattern.target_swath_m
    varied = diameter_mm.size > 1 and np.ptp(diameter_mm) > 1e-6
    if pos.shape[0]:
        if varied:
            points = ax.scatter(pos[:, 0], pos[:, 1], c=diameter_mm, cmap="viridis", s=6, alpha=0.8,
                                linewidths=0, zorder=3)
            if colorbar:
                ax.figure.colorbar(points, ax=ax, label="granule diameter (mm)", shrink=0.85)
        else:
            ax.scatter(pos[:, 0], pos[:, 1], color=LINE, s=6, alpha=0.7, linewidths=0, zorder=3,
                       label="landing point")
    else:
        _note(ax, "nothing landed")
    ax.plot([0], [0], marker="P", color="black", ms=9, ls="none", zorder=4, label="spinner")
    for x in (-half, half):
        ax.axvline(x, color=TARGET, ls="--", lw=1.2, zorder=2)
    ax.plot([], [], color=TARGET, ls="--", lw=1.2, label=f"target bout edges (W = {2 * half:g} m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x, across (m)")
    ax.set_ylabel("y, along the track (m)")
    ax.grid(True, color="#e5e5e5", lw=0.6, zorder=0)
    ax.set_axisbelow(True)
    shown = f"{pos.shape[0]} of {result.landing.position_m.shape[0]}" \
        if pos.shape[0] < result.landing.position_m.shape[0] else f"{pos.shape[0]}"
    ax.set_title(f"Landing points ({shown} granules)")
    ax.legend(loc="best", fontsize="small", framealpha=0.9)
    _forward_arrow(ax)


def overlapped_field(trays: pattern.Trays, bout_width_m: float, driving: str,
                     tray_index: np.ndarray) -> np.ndarray:
    """Mass per tray of the field from passes at x = j W (all j), at the tray indices given.

    Racetrack: every pass as it is; back-and-forth: odd passes mirrored about their own
    axis. On the target bout's trays this equals `pattern.bout_pattern`."""
    n = pattern.bout_tray_count(bout_width_m, trays.width_m)
    if driving not in pattern.DRIVING:
        raise ValueError(f"unknown driving pattern {driving!r}")
    m = trays.count // 2
    k = np.asarray(tray_index, dtype=np.int64)
    field = np.zeros(k.shape)
    j_lo = int(math.floor((k.min() - m) / n)) - 1 if k.size else 0
    j_hi = int(math.ceil((k.max() + m) / n)) + 1 if k.size else 0
    for j in range(j_lo, j_hi + 1):
        i = k - j * n
        if driving == "back-and-forth" and j % 2:
            i = -i
        inside = np.abs(i) <= m
        field[inside] += trays.mass_kg[i[inside] + m]
    return field


def transverse_pattern(ax, result, legend: bool = True) -> None:
    """Single-pass tray masses (bars) and the overlapped pattern at the target swath (line),
    both relative to the overlapped mean; the target bout shaded; CV at target in the title."""
    trays = result.trays
    p = result.scene.pattern
    W, w = p.target_swath_m, trays.width_m
    cv = result.metrics.cv_percent_at_target
    if trays.total_kg <= 0:
        _note(ax, "nothing landed")
        ax.set_xlim(trays.center_m[0] - w, trays.center_m[-1] + w)
        ax.set_ylim(0, 100)
        ax.set_xlabel("x, across (m)")
        ax.set_ylabel("rate (% of mean at target swath)")
        ax.set_title("Transverse pattern: nothing landed")
        return
    mean = float(np.mean(pattern.bout_pattern(trays, W, p.driving)))
    m = trays.count // 2
    n = pattern.bout_tray_count(W, w)
    half_span = max(m, int(math.ceil(1.5 * n)))
    k = np.arange(-half_span, half_span + 1)
    field = overlapped_field(trays, W, p.driving, k)

    ax.axvspan(-W / 2, W / 2, color="#fff2cc", zorder=0, label="target bout")
    ax.axhline(100.0, color="#999999", lw=0.8, ls=":", zorder=1)
    ax.bar(trays.center_m, 100.0 * trays.mass_kg / mean, width=0.9 * w, color=BAR, edgecolor="#6baed6",
           lw=0.6, zorder=2, label="single pass")
    ax.step(k * w, 100.0 * field / mean, where="mid", color=LINE, lw=1.8, zorder=3,
            label="overlapped passes")
    ax.set_xlim((-half_span - 0.5) * w, (half_span + 0.5) * w)
    ax.set_ylim(0, 1.25 * max(100.0 * field.max() / mean, 100.0 * trays.mass_kg.max() / mean, 100.0))
    ax.set_xlabel("x, across (m)")
    ax.set_ylabel("rate (% of mean at target swath)")
    cv_text = "no CV" if cv is None or not np.isfinite(cv) else f"CV {cv:.1f} %"
    ax.set_title(f"Transverse pattern: {cv_text} at {W:g} m ({p.driving})")
    ax.grid(True, axis="y", color="#e5e5e5", lw=0.6, zorder=0)
    ax.set_axisbelow(True)
    if legend:
        ax.legend(loc="upper center", ncol=3, fontsize="small", framealpha=0.9)


def cv_vs_bout_width(ax, result) -> None:
    """CV against bout width with the threshold, the effective swath and the target swath."""
    metrics, p = result.metrics, result.scene.pattern
    widths = np.asarray(metrics.curve_bout_width_m, dtype=float)
    cvs = np.asarray(metrics.curve_cv_percent, dtype=float)
    if widths.size == 0 and result.trays.total_kg > 0:
        widths, cvs = pattern.cv_curve(result.trays, p.driving)
    threshold = float(metrics.cv_threshold_percent)
    target = float(metrics.target_swath_m)
    effective = float(metrics.effective_swath_m or 0.0)
    cv_target = metrics.cv_percent_at_target

    finite = np.isfinite(cvs)
    top = max(2.0 * threshold, 1.1 * float(cvs[finite].max()) if finite.any() else 0.0)
    top = min(top, max(100.0, 2.0 * threshold))
    ax.axhspan(0, threshold, color="#e5f5e0", zorder=0)
    ax.axhline(threshold, color=THRESHOLD, ls="--", lw=1.3, zorder=2, label=f"threshold {threshold:g} %")
    if widths.size:
        ax.plot(widths, cvs, color=LINE, marker="o", ms=3.5, lw=1.6, zorder=3, label=f"CV ({p.driving})")
    if effective > 0:
        ax.axvline(effective, color=EFFECTIVE, lw=2.2, zorder=2, label=f"effective swath {effective:g} m")
    ax.axvline(target, color=TARGET, ls=":", lw=1.6, zorder=2.5, label=f"target swath {target:g} m")
    if cv_target is not None and np.isfinite(cv_target):
        label = f"CV at target {cv_target:.1f} %"
        ci = metrics.cv_ci_percent
        if ci is not None and len(ci) == 2 and np.all(np.isfinite(ci)):
            lo, hi = float(min(ci)), float(max(ci))
            ax.plot([target, target], [lo, min(hi, top)], color="black", lw=1.4, zorder=3.5,
                    solid_capstyle="butt")
            ax.plot([target, target], [lo, hi], ls="none", marker="_", ms=10, color="black", zorder=3.5)
            label += f" (95 % CI {lo:.1f}-{hi:.1f} %)"
        ax.plot([target], [min(cv_target, top)], marker="*", ms=13, color="black", mfc="#ffd700",
                ls="none", zorder=4, label=label)
    if not widths.size:
        _note(ax, "nothing landed")
    right = max(float(widths.max()) if widths.size else 0.0, target, effective)
    ax.set_xlim(0, 1.03 * right + 0.25)
    ax.set_ylim(0, top)
    ax.set_xlabel("bout width W (m)")
    ax.set_ylabel("CV (%)")
    ax.set_title("Coefficient of variation against bout width")
    ax.grid(True, color="#e5e5e5", lw=0.6, zorder=0)
    ax.set_axisbelow(True)
    ax.legend(loc="upper left", fontsize="small", framealpha=0.9)


SIMULATION_PLOTS = ("plan_view.png", "landing.png", "pattern.png", "cv_curve.png")


def write_simulation_plots(result, out_dir) -> list[Path]:
    """Write the SIMULATION_PLOTS (plan_view.png, landing.png, pattern.png and cv_curve.png)
    into out_dir (created)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, draw in (("plan_view.png", plan_view), ("landing.png", landing_scatter),
                       ("pattern.png", transverse_pattern), ("cv_curve.png", cv_vs_bout_width)):
        if draw is plan_view:  # square plot, legend on the right: placed by hand
            fig = Figure(figsize=FIGSIZE_IN, dpi=DPI)
            FigureCanvasAgg(fig)
            ax = fig.add_axes((0.1, 0.1, 0.56, 0.82))
        else:
            fig = _new_figure()
            ax = fig.add_subplot()
        draw(ax, result)
        path = out / name
        fig.savefig(path, dpi=DPI)
        written.append(path)
    return written
