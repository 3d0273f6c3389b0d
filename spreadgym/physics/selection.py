"""Which spinner model a scene gets: the cheapest one that is exact enough for it."""

from __future__ import annotations

from spreadgym.errors import ConfigError
from spreadgym.scene import Scene

MODELS = ("auto", "pymunk")


def choose_model(scene: Scene, requested: str = "auto") -> tuple[str, str]:
    """(model name, reason). `requested` other than auto is honoured as it is."""
    if requested not in MODELS:
        raise ConfigError("model", f"unknown model {requested!r}; allowed: {', '.join(MODELS)}")
    if requested != "auto":
        return requested, "requested"
    return "pymunk", "the full plan-view model serves every scene"
