"""Pictures of an environment's state: `rgb_array` frames and the `human` window.

A frame has three panels:

* the spinner (plan view, machine frame): disc, vanes, deflectors, granule paths over
  the disc when the model recorded them, and straight departure rays
  (`spreadgym.viz.plots.plan_view`);
* the field (plan view): straight lines from each granule's launch point to where it
  lands, for the first `render.trajectories` granules (in still air with the machine
  standing the path over the ground is exactly straight; with wind or forward speed
  this is a chord of it), and the row of trays across the track;
* the tray test: single-pass tray masses and the overlapped pattern at the target
  swath, with the CV (`spreadgym.viz.plots.transverse_pattern`);
* a few lines of text: the job, the settings, CV, effective swath and reward.

matplotlib is imported only when a frame is drawn, and frames are drawn on an Agg
canvas of their own (no pyplot, no display). `human` mode uses pyplot to show the
frame in a window; on a non-interactive backend (no display) it draws but shows
nothing.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from spreadgym.config.scene import Scene
from spreadgym.envs.common.actions import Settings
from spreadgym.envs.common.task import Context
from spreadgym.physics.geometry import vane_segments


def draw_frame(
    scene: Scene,
    result,
    width_px: int,
    height_px: int,
    trajectories: int,
    lines: list[str],
) -> np.ndarray:
    """uint8 (height_px, width_px, 3) picture of `scene` and its last `result` (may be None)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    dpi = 100
    fig = Figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    grid = fig.add_gridspec(3, 2, height_ratios=[1.1, 0.9, 0.25], hspace=0.5, wspace=0.3,
                            left=0.1, right=0.97, top=0.95, bottom=0.03)
    ax_disc = fig.add_subplot(grid[0, 0])
    ax_field = fig.add_subplot(grid[0, 1])
    ax_trays = fig.add_subplot(grid[1, :])
    ax_text = fig.add_subplot(grid[2, :])
    if result is None:
        _draw_spinner(ax_disc, scene)
        _draw_field(ax_field, scene, None, 0)
        _draw_no_trays(ax_trays, scene)
    else:
        from spreadgym.viz import plots

        plots.plan_view(ax_disc, result, max_tracks=15, max_rays=60, legend=False)
        ax_disc.set_title(f"spinner {scene.spinner.rpm:.0f} rpm", fontsize=8)
        _draw_field(ax_field, scene, result, trajectories)
        plots.transverse_pattern(ax_trays, result, legend=True)
    for ax in (ax_disc, ax_field, ax_trays):
        _small_fonts(ax)
    ax_text.axis("off")
    ax_text.text(0.0, 1.0, "\n".join(lines), va="top", ha="left", fontsize=7, family="monospace",
                 transform=ax_text.transAxes)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    frame = np.full((height_px, width_px, 3), 255, dtype=np.uint8)
    h, w = min(height_px, rgba.shape[0]), min(width_px, rgba.shape[1])
    frame[:h, :w] = rgba[:h, :w, :3]  # the canvas can be a pixel off the requested size
    return frame


def _small_fonts(ax) -> None:
    ax.title.set_fontsize(8)
    ax.xaxis.label.set_fontsize(7)
    ax.yaxis.label.set_fontsize(7)
    ax.tick_params(labelsize=6)
    for text in ax.texts:
        text.set_fontsize(6)
    legend = ax.get_legend()
    if legend is not None:
        for text in legend.get_texts():
            text.set_fontsize(6)


def _draw_spinner(ax, scene: Scene) -> None:
    """Disc, vanes (spinner angle 0), deflectors and feed point, before any run."""
    radius = scene.spinner.radius_m
    t = np.linspace(0.0, 2.0 * np.pi, 181)
    ax.fill(radius * np.cos(t), radius * np.sin(t), color="0.93", zorder=0)
    ax.plot(radius * np.cos(t), radius * np.sin(t), color="0.4", lw=1)
    inner, outer = vane_segments(scene)
    for a, b in zip(inner, outer):
        ax.plot([a[0], b[0]], [a[1], b[1]], color="0.55", lw=2)
    reach = 2.0 * radius
    for plate in scene.deflectors:
        (x0, y0), (x1, y1) = plate.endpoints()
        ax.plot([x0, x1], [y0, y1], color="k", lw=2)
        reach = max(reach, 1.1 * max(abs(x0), abs(y0), abs(x1), abs(y1)))
    feed = scene.feed
    ax.plot(feed.radius_m * np.cos(feed.angle_rad), feed.radius_m * np.sin(feed.angle_rad), "v",
            color="tab:green", ms=5)
    ax.set_xlim(-reach, reach)
    ax.set_ylim(-reach, reach)
    ax.set_aspect("equal")
    ax.set_title(f"spinner {scene.spinner.rpm:.0f} rpm", fontsize=8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y, forward (m)")


def _draw_field(ax, scene: Scene, result, trajectories: int) -> None:
    half = max(scene.pattern.target_swath_m, 1.0)
    if result is not None and result.landing.position_m.shape[0]:
        launch = result.launch
        start = launch.position_m[launch.departed]
        end = result.landing.position_m
        k = min(trajectories, end.shape[0])
        if k:
            segs_x = np.stack([start[:k, 0], end[:k, 0], np.full(k, np.nan)], axis=1).ravel()
            segs_y = np.stack([start[:k, 1], end[:k, 1], np.full(k, np.nan)], axis=1).ravel()
            ax.plot(segs_x, segs_y, color="tab:blue", lw=0.3, alpha=0.4)
        ax.plot(end[:, 0], end[:, 1], ".", color="tab:brown", ms=1.5)
        half = max(half, float(np.max(np.abs(end))) * 1.05)
    w = scene.pattern.tray_width_m
    ax.axhline(0.0, color="0.5", lw=0.5)
    ax.plot([-0.5 * scene.pattern.target_swath_m, 0.5 * scene.pattern.target_swath_m], [0, 0], color="tab:green",
            lw=3, alpha=0.6, solid_capstyle="butt")
    ax.plot(0, 0, "o", color="k", ms=3)
    ax.set_xlim(-half - w, half + w)
    ax.set_ylim(-half - w, half + w)
    ax.set_aspect("equal")
    ax.set_title("field: flights and landings", fontsize=8)
    ax.tick_params(labelsize=6)
    ax.set_xlabel("x (m)", fontsize=7)


def _draw_no_trays(ax, scene: Scene) -> None:
    half = scene.pattern.target_swath_m
    ax.axvspan(-0.5 * half, 0.5 * half, color="tab:green", alpha=0.08)
    ax.set_xlim(-half, half)
    ax.set_yticks([])
    ax.set_title("tray test: nothing measured yet")
    ax.set_xlabel("across the track (m)")


class HumanViewer:
    """A pyplot window that shows frames (lazy pyplot import)."""

    def __init__(self, fps: float):
        self.fps = float(fps)
        self._fig = None
        self._image = None

    def show(self, frame: np.ndarray) -> None:
        import matplotlib.pyplot as plt

        if self._fig is None or not plt.fignum_exists(self._fig.number):
            h, w = frame.shape[:2]
            self._fig = plt.figure(figsize=(w / 100, h / 100), dpi=100)
            ax = self._fig.add_axes([0, 0, 1, 1])
            ax.axis("off")
            self._image = ax.imshow(frame)
        else:
            self._image.set_data(frame)
        interactive = getattr(type(self._fig.canvas), "required_interactive_framework", None) is not None
        if interactive:
            plt.pause(1.0 / self.fps)
        else:  # no display: keep the picture up to date, show nothing
            self._fig.canvas.draw()

    def close(self) -> None:
        if self._fig is not None:
            import matplotlib.pyplot as plt

            plt.close(self._fig)
            self._fig = None
            self._image = None


def frame_lines(context: Optional[Context], settings: Optional[Settings], score, reward_value, extra=()) -> list[str]:
    lines = []
    if context is not None:
        c = context
        lines.append(f"job: {c.fertilizer} on {c.spinner_material}, target swath {c.target_swath_m:g} m, "
                     f"forward {c.forward_speed_m_s:.2f} m/s, wind ({c.wind_m_s[0]:.2f}, {c.wind_m_s[1]:.2f}) m/s")
    if settings is not None:
        pitch = ", ".join(f"{p:.1f}" for p in settings.pitch_deg)
        defl = ", ".join(f"{a:.1f}" for a in settings.deflector_angle_deg)
        lines.append(f"settings: {settings.rpm:.0f} rpm, pitch [{pitch}] deg"
                     + (f", deflectors [{defl}] deg" if defl else ""))
    if score is not None:
        lines.append(f"CV {score.cv_percent:.1f} %, effective swath {score.effective_swath_m:g} m, "
                     f"landed {100 * score.landed_fraction:.0f} %, reward {reward_value:.3f}")
    lines.extend(extra)
    return lines
