"""Physical constants used across the models, each defined once (SI units)."""

GRAVITY_M_S2 = 9.81
"""Standard gravity, m/s^2 (the value the calibration and flight references use)."""

SPHERE_INERTIA_FACTOR = 0.4
"""kappa in I = kappa m r^2 for a solid sphere (granules are modelled as solid spheres)."""
