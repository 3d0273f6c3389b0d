"""Which spinner model a scene gets: the cheapest one that is exact enough for it.

`compiled` integrates the full model's contact laws granule by granule (numba), about
200 times faster than `pymunk` and as fast as the closed forms. Measured against the
converged full model on the reference family (docs/bench/references, docs/fidelity.md):
the CV at the target within 0.5 pp on every scene, the effective swath equal on all but
one (a tray off where the CV curve runs along the threshold), the departure-azimuth
histograms within a total variation of 0.05 and the median time on the spinner within
3 %. So `auto` takes `compiled` for every scene inside the envelope that measurement
covers (`VALIDATED`), and the full `pymunk` model outside it, saying why.

`analytic` (closed forms; exact for its own assumptions, no bounces on the disc, disc
drag to first order) departs from the full model by 1-9 pp in CV on that family, so it
is used only when asked for, as is `spring-damper` (the paper's contact model with the
measured contact time, never cheaper than pymunk).
"""

from __future__ import annotations

from spreadgym.config.scene import Scene
from spreadgym.errors import ConfigError

MODELS = ("auto", "analytic", "pymunk", "spring-damper", "compiled")


# The envelope the compiled model was measured in against converged pymunk references
# (configs/references.yaml plus the edges of the environments' action ranges).
VALIDATED = {
    "rpm": (200.0, 1100.0),
    "pitch_deg": (-30.0, 30.0),
    "drop_height_m": (0.0, 0.08),
    "radius_m": (0.15, 0.30),
}


def outside_validated(scene: Scene) -> list[str]:
    """What puts `scene` outside the envelope `compiled` was validated in (empty: inside)."""
    pitches = scene.vanes.pitch_deg if isinstance(scene.vanes.pitch_deg, list) else [scene.vanes.pitch_deg]
    values = {"rpm": [scene.spinner.rpm], "pitch_deg": pitches, "drop_height_m": [scene.feed.drop_height_m],
              "radius_m": [scene.spinner.radius_m]}
    out = []
    for key, (lo, hi) in VALIDATED.items():
        bad = [v for v in values[key] if not lo - 1e-9 <= v <= hi + 1e-9]
        if bad:
            out.append(f"{key} {bad[0]:g} outside [{lo:g}, {hi:g}]")
    return out


def choose_model(scene: Scene, requested: str = "auto") -> tuple[str, str]:
    """(model name, reason). `requested` other than auto is honoured as it is."""
    if requested not in MODELS:
        raise ConfigError("model", f"unknown model {requested!r}; allowed: {', '.join(MODELS)}")
    if requested != "auto":
        return requested, "requested"
    outside = outside_validated(scene)
    if outside:
        return "pymunk", (f"auto: {'; '.join(outside)}, where the fast compiled model has not been checked "
                          "against the full model, so the full model runs")
    return "compiled", ("auto: the compiled model (the full model's contact laws per granule) matches the "
                        "converged full model within 0.5 pp of CV on the reference family, ~200x cheaper")
