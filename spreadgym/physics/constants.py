"""Physical constants used across the models, each defined once (SI units)."""

GRAVITY_M_S2 = 9.81
"""Gravity, m/s^2: standard gravity (9.80665) rounded, the value the calibration and flight references use."""

SPHERE_INERTIA_FACTOR = 0.4
"""kappa in I = kappa m r^2 for a solid sphere (granules are modelled as solid spheres)."""
