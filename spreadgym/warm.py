"""Compile every numba kernel once and keep it in numba's cache: `python -m spreadgym.warm`.

The kernels are compiled on first use and cached next to their sources (`cache=True`);
the spinner kernel alone takes tens of seconds to compile (docs/performance.md, cold
start). `make` runs this module right after installing, so that the first simulation or
environment step of a fresh install only loads cached machine code. It runs small
scenes through every path a user reaches (one disc, plates, twin discs, a flight with a
direction and with the Magnus lift, a batch, a pooled reference) with the argument
types those paths pass, which are the signatures numba caches.
"""

from __future__ import annotations

import sys
import time

SCENES = (  # (scene, overrides): every path of the pipeline, at a few granules each
    ("paper", {}),
    ("paper-deflectors", {}),
    ("twin-field", {}),
    ("field", {"flight.wind_m_s": [1.0, 0.0], "flight.magnus": True, "pattern.driving": "racetrack"}),
    ("paper", {"sim.angle_copies": 1}),
)
GRANULES = 64


def warm() -> float:
    """Run every compiled path once; returns the seconds it took."""
    started = time.perf_counter()
    from spreadgym.config.materials import load_library
    from spreadgym.config.scene import load_scene
    from spreadgym.spread.batch import run_batch
    from spreadgym.spread.pipeline import run_scene
    from spreadgym.spread.reference import pool_runs, reference_from

    library = load_library()
    scenes = [load_scene(name, {"sim.granules": GRANULES, **overrides}) for name, overrides in SCENES]
    for scene in scenes:
        run_scene(scene, library=library)
    run_batch(scenes, library=library)
    reference_from(scenes[0], pool_runs(scenes[0], 2, library=library))
    return time.perf_counter() - started


def main() -> int:
    print("spreadgym: compiling and caching the numba kernels (once per install: under a minute on two cores) ...",
          file=sys.stderr, flush=True)
    print(f"spreadgym: kernels ready in {warm():.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
