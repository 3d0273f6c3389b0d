"""Which spinner model a scene gets: the cheapest one that is exact enough for it.

`analytic` is exact (closed forms, checked to 1e-9 against numerical solves) for a
granule that starts on the disc, including the bouncing catch by the vanes. It has
no bounces on the disc after a drop. Measured against pymunk on the paper spinner
at drop 0 (400 granules, 200-1100 rpm, pitch -15..0 deg): departure speed within
0.09 % and direction within 0.09 deg at the measured vane restitution 0.43.
So `auto` takes analytic when the feed does not drop onto the disc, and the full
pymunk model otherwise. `spring-damper` (the paper's contact model, with the
measured contact time) is never cheaper and agrees with pymunk within 0.3 % on
departure speed, so it is used only when asked for.
"""

from __future__ import annotations

from spreadgym.config.scene import Scene
from spreadgym.errors import ConfigError

MODELS = ("auto", "analytic", "pymunk", "spring-damper", "compiled")


def choose_model(scene: Scene, requested: str = "auto") -> tuple[str, str]:
    """(model name, reason). `requested` other than auto is honoured as it is."""
    if requested not in MODELS:
        raise ConfigError("model", f"unknown model {requested!r}; allowed: {', '.join(MODELS)}")
    if requested != "auto":
        return requested, "requested"
    if scene.feed.drop_height_m > 0:
        return "pymunk", (f"auto: the feed drops {scene.feed.drop_height_m:g} m, and bounces on the disc "
                          "need the full model")
    return "analytic", "auto: the feed does not drop onto the disc, so the closed form is exact (no disc bounces)"
