"""Which spinner model a scene gets: the cheapest one that is exact enough for it.

`analytic` is exact (closed forms, checked to 1e-11 against solve_ivp) for a granule
that starts on the disc and is caught by a vane in a plastic impact. It has no
bounces: on the disc after a drop, or off the vane at the catch. Measured on the
paper spinner at drop 0 (400 granules), analytic against pymunk:
- vane restitution 0: departure speed within 0.22 % (free and locked);
- restitution 0.43: up to 1.3 % (locked, pitch -15 deg, 1100 rpm) and 1.4 % (free,
  radial, 500 rpm): the bouncing catch is missing from the closed form.
So `auto` takes analytic when nothing bounces (no drop, a nearly plastic vane), and
the full pymunk model otherwise. `spring-damper` (the paper's contact model, with the
measured contact time) is never cheaper and agrees with pymunk within 0.3 % on
departure speed, so it is used only when asked for.
"""

from __future__ import annotations

from typing import Optional

from spreadgym.contacts import Contacts, resolve_contacts
from spreadgym.errors import ConfigError
from spreadgym.materials import load_library
from spreadgym.scene import Scene

MODELS = ("auto", "analytic", "pymunk", "spring-damper")
PLASTIC_ENOUGH = 0.1  # vane restitution below which the catch bounce is negligible


def choose_model(scene: Scene, requested: str = "auto", contacts: Optional[Contacts] = None) -> tuple[str, str]:
    """(model name, reason). `requested` other than auto is honoured as it is.

    `contacts` defaults to the scene's pairs from the shipped library.
    """
    if requested not in MODELS:
        raise ConfigError("model", f"unknown model {requested!r}; allowed: {', '.join(MODELS)}")
    if requested != "auto":
        return requested, "requested"
    if scene.feed.drop_height_m > 0:
        return "pymunk", (f"auto: the feed drops {scene.feed.drop_height_m:g} m, and bounces on the disc "
                          "need the full model")
    if contacts is None:
        contacts = resolve_contacts(scene, load_library())
    if contacts.vane_restitution > PLASTIC_ENOUGH:
        return "pymunk", (f"auto: vane restitution {contacts.vane_restitution:g}: the bouncing catch "
                          "changes the departure speed by up to 1.4 %, beyond the closed form")
    return "analytic", "auto: no drop and no catch bounce that matters, so the closed form is exact enough"
