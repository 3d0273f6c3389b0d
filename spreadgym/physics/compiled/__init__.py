"""The `compiled` spinner model: the pymunk model's contact laws, one granule at a time,
integrated by an event-driven fourth-order stepper compiled with numba
(`model.simulate_compiled`). The package imports nothing itself, so a module may use
its leaf modules (`options`, `pcg64`) without loading the model."""
