"""The `compiled` spinner model: the pymunk model's contact laws, one granule at a time,
integrated by an event-driven fourth-order stepper compiled with numba."""

from spreadgym.physics.compiled.model import simulate_compiled

__all__ = ["simulate_compiled"]
