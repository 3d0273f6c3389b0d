"""Contact calibration from the seed paper's measurements (Eqs. 1, 2, 8-10; Table 3).

Small pure functions, SI units throughout:

* bounce test -> coefficient of restitution (Eq. 1),
* high-speed video frames -> contact (impact) time (Eq. 2),
* restitution + contact time + mass -> linear spring-dashpot stiffness and damping
  (Eqs. 8-10), their inverses, and the explicit integrator's stability limit,
* a consistency check of the paper's printed stiffness/damping (Table 3),
* the default spring-dashpot of a fertilizer-surface pair, always computed from the
  measured restitution and impact time with the actual granule mass, never from the
  paper's printed stiffness or damping.

Bad input raises CalibrationError (a SpreadgymError, so the CLI exits with status 2)
naming the parameter, the value and the allowed range. No function returns NaN.
"""

from __future__ import annotations

import math
import statistics
import warnings
from dataclasses import asdict, dataclass
from typing import Any, Optional

from spreadgym.config.materials import MaterialLibrary, load_library
from spreadgym.errors import SpreadgymError

# Rule deciding whether a printed Table 3 row is consistent (see docs/calibration.md).
MEDIAN_MASS_FACTOR = 3.0
"""A row is flagged when the mass implied by its printed stiffness is more than this
factor away from the median of all rows' stiffness-implied masses."""

STIFFNESS_DAMPING_MASS_FACTOR = 2.0
"""A row is flagged when the masses implied by its printed stiffness and by its printed
damping differ by more than this factor (they should be one and the same granule)."""


class CalibrationError(SpreadgymError):
    """A calibration input is out of range; the message names parameter, value, range."""

    def __init__(self, parameter: str, value: Any, allowed: str):
        self.parameter = parameter
        self.value = value
        self.allowed = allowed
        super().__init__(f"{parameter}: {_show(value)} {allowed}")

    def __reduce__(self):  # so the error crosses process boundaries (worker pools) intact
        return type(self), (self.parameter, self.value, self.allowed)


class PaperTableWarning(UserWarning):
    """The pair's printed Table 3 row failed the consistency check."""


def _show(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def check_finite(value: Any, name: str) -> float:
    """`value` as a float; a CalibrationError naming `name` unless it is a finite number."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise CalibrationError(name, repr(value), "is not a number") from None
    if not math.isfinite(number):
        raise CalibrationError(name, number, "is not a finite number")
    return number


def check_positive(value: Any, name: str) -> float:
    """Return `value` as float; raise CalibrationError unless 0 < value < inf."""
    number = check_finite(value, name)
    if number <= 0.0:
        raise CalibrationError(name, number, "outside (0, inf): must be positive")
    return number


def check_non_negative(value: Any, name: str) -> float:
    """Return `value` as float; raise CalibrationError unless 0 <= value < inf."""
    number = check_finite(value, name)
    if number < 0.0:
        raise CalibrationError(name, number, "outside [0, inf): must not be negative")
    return number


def check_restitution(value: Any, name: str = "restitution") -> float:
    """Return the coefficient of restitution as float; allowed range (0, 1]."""
    number = check_finite(value, name)
    if not 0.0 < number <= 1.0:
        raise CalibrationError(name, number, "outside (0, 1]")
    return number


def check_damping_ratio(value: Any, name: str = "damping_ratio") -> float:
    """Return the damping ratio as float; allowed range [0, 1) (under-damped contact)."""
    number = check_finite(value, name)
    if not 0.0 <= number < 1.0:
        raise CalibrationError(name, number, "outside [0, 1): the contact must be under-damped")
    return number


# --- measurements -----------------------------------------------------------------------


def restitution_from_bounce(h_in_m: float, h_out_m: float, range_m: float) -> float:
    """Coefficient of restitution from a drop-and-bounce test (paper Eq. 1), dimensionless.

    A granule dropped from rest at height `h_in_m` (m) hits a horizontal plate with speed
    sqrt(2 g h_in). It rebounds on a projectile of apex height `h_out_m` (m) above the
    plate and horizontal range `range_m` (m, take-off to landing on the plate level).
    Apex h and range d of a projectile launched at angle theta give tan(theta) = 4 h / d;
    its vertical take-off speed is sqrt(2 g h) = v sin(theta). Hence
    e = v_out / v_in = sqrt(h_out / h_in) / sin(atan(4 h_out / d)); g cancels.
    This is the ratio of speed magnitudes, as in the paper (not only the normal part).
    """
    h_in = check_positive(h_in_m, "h_in_m")
    h_out = check_positive(h_out_m, "h_out_m")
    d = check_positive(range_m, "range_m")
    theta = math.atan(4.0 * h_out / d)
    e = math.sqrt(h_out / h_in) / math.sin(theta)
    if e > 1.0:
        raise CalibrationError(
            "restitution_from_bounce",
            e,
            f"outside (0, 1]: h_in_m={h_in:g}, h_out_m={h_out:g}, range_m={d:g} "
            "describe a rebound faster than the impact",
        )
    return e


def contact_time_from_frames(
    h_in_m: float,
    v_in_m_s: float,
    h_out_m: float,
    v_out_m_s: float,
    frame_interval_s: float = 1e-3,
) -> float:
    """Contact (impact) time from two consecutive high-speed frames (paper Eq. 2), seconds.

    The last frame before impact shows the granule `h_in_m` (m) above the surface moving
    at `v_in_m_s` (m/s); the first frame after shows it `h_out_m` (m) away moving at
    `v_out_m_s` (m/s). The frames are `frame_interval_s` apart (1 ms at 1000 frame/s), so
    contact time = frame_interval - h_in/v_in - h_out/v_out. It must come out positive.
    """
    h_in = check_non_negative(h_in_m, "h_in_m")
    v_in = check_positive(v_in_m_s, "v_in_m_s")
    h_out = check_non_negative(h_out_m, "h_out_m")
    v_out = check_positive(v_out_m_s, "v_out_m_s")
    frame = check_positive(frame_interval_s, "frame_interval_s")
    t = frame - h_in / v_in - h_out / v_out
    if t <= 0.0:
        raise CalibrationError(
            "contact_time",
            t,
            f"outside (0, {frame:g}] s: the flight times h_in/v_in + h_out/v_out = "
            f"{h_in / v_in + h_out / v_out:g} s leave no time for contact in one frame interval",
        )
    return t


# --- linear spring-dashpot (Eqs. 8-10) --------------------------------------------------


def damping_ratio(e: float) -> float:
    """Damping ratio zeta (dimensionless) giving restitution `e` (Eq. 9).

    zeta = -ln e / sqrt(pi^2 + ln^2 e); e = 1 gives 0, e -> 0 gives zeta -> 1.
    """
    e = check_restitution(e)
    log_e = math.log(e)
    return abs(log_e) / math.sqrt(math.pi**2 + log_e**2)  # abs: no -0.0 for e = 1


def restitution_from_damping_ratio(zeta: float) -> float:
    """Restitution (dimensionless) of a linear spring-dashpot with damping ratio `zeta`.

    e = exp(-pi zeta / sqrt(1 - zeta^2)), the inverse of `damping_ratio`; zeta in [0, 1).
    """
    zeta = check_damping_ratio(zeta)
    return math.exp(-math.pi * zeta / math.sqrt(1.0 - zeta**2))


def stiffness(mass: float, e: float, contact_time: float) -> float:
    """Spring stiffness k (N/m) giving contact time `contact_time` (s) to mass `mass` (kg).

    Eq. 8: the contact lasts half a damped period, t = pi / omega_d, so
    k = pi^2 m / ((1 - zeta^2) t^2), zeta = damping_ratio(e).
    """
    m = check_positive(mass, "mass")
    t = check_positive(contact_time, "contact_time")
    zeta = damping_ratio(e)
    return math.pi**2 * m / ((1.0 - zeta**2) * t**2)


def damping(mass: float, e: float, contact_time: float) -> float:
    """Dashpot coefficient c (N s/m) = 2 zeta sqrt(k m) (Eq. 10); 0 when e = 1."""
    k = stiffness(mass, e, contact_time)
    return 2.0 * damping_ratio(e) * math.sqrt(k * float(mass))


@dataclass(frozen=True)
class SpringDashpot:
    """Linear normal contact: stiffness (N/m), damping (N s/m), damping ratio (-)."""

    stiffness_n_per_m: float
    damping_ns_per_m: float
    damping_ratio: float


CONTACT_TIME_RANGE_S = (1e-7, 1e-2)  # measured granule impacts: about 1e-4 s; the materials' impact_time_s cap


def check_contact_time(value: Any, name: str = "contact_time_s") -> float:
    """A contact time (s) as float; allowed range CONTACT_TIME_RANGE_S."""
    lo, hi = CONTACT_TIME_RANGE_S
    number = check_finite(value, name)
    if not lo <= number <= hi:
        raise CalibrationError(name, number, f"outside [{lo:g}, {hi:g}] s: not a granule impact")
    return number


def spring_dashpot(mass_kg: float, restitution: float, contact_time_s: float) -> SpringDashpot:
    """Spring-dashpot reproducing `restitution` and `contact_time_s` (s) for `mass_kg` (kg)."""
    m = check_positive(mass_kg, "mass_kg")
    t = check_contact_time(contact_time_s)
    e = check_restitution(restitution)
    zeta = damping_ratio(e)
    k = math.pi**2 * m / ((1.0 - zeta**2) * t**2)
    return SpringDashpot(
        stiffness_n_per_m=k,
        damping_ns_per_m=2.0 * zeta * math.sqrt(k * m),
        damping_ratio=zeta,
    )


def contact_time_from_stiffness(mass: float, k: float, zeta: float) -> float:
    """Contact time (s) of mass `mass` (kg) on a spring `k` (N/m) with damping ratio `zeta`.

    t = pi / omega_d = pi sqrt(m / ((1 - zeta^2) k)), the inverse of Eq. 8.
    """
    m = check_positive(mass, "mass")
    k = check_positive(k, "stiffness")
    zeta = check_damping_ratio(zeta)
    return math.pi * math.sqrt(m / ((1.0 - zeta**2) * k))


def mass_from_stiffness(k: float, e: float, t: float) -> float:
    """Mass (kg) for which stiffness `k` (N/m), restitution `e` give contact time `t` (s).

    m = k (1 - zeta^2) t^2 / pi^2 (Eq. 8 solved for m).
    """
    k = check_positive(k, "stiffness")
    t = check_positive(t, "contact_time")
    zeta = damping_ratio(e)
    return k * (1.0 - zeta**2) * t**2 / math.pi**2


def mass_from_damping(c: float, e: float, t: float) -> float:
    """Mass (kg) for which dashpot `c` (N s/m), restitution `e` give contact time `t` (s).

    With k from Eq. 8, c = 2 zeta sqrt(k m) = 2 zeta pi m / (sqrt(1 - zeta^2) t), so
    m = c t sqrt(1 - zeta^2) / (2 zeta pi). Needs e < 1 (an undamped contact says
    nothing about the mass) and c > 0.
    """
    c = check_positive(c, "damping")
    t = check_positive(t, "contact_time")
    e = check_restitution(e)
    if e == 1.0:
        raise CalibrationError(
            "restitution", e, "outside (0, 1): a mass follows from damping only if e < 1"
        )
    zeta = damping_ratio(e)
    return c * t * math.sqrt(1.0 - zeta**2) / (2.0 * zeta * math.pi)


def critical_time_step(mass: float, k: float, c: float) -> float:
    """Largest stable time step (s) of symplectic Euler / central differences.

    For m x'' + c x' + k x = 0: dt_crit = (2 / omega_n) (sqrt(1 + zeta^2) - zeta),
    omega_n = sqrt(k / m), zeta = c / (2 sqrt(k m)). Mass in kg, k in N/m, c in N s/m.
    DEM practice stays well below it (contact time / 20 ... / 50).
    """
    m = check_positive(mass, "mass")
    k = check_positive(k, "stiffness")
    c = check_non_negative(c, "damping")
    omega_n = math.sqrt(k / m)
    zeta = c / (2.0 * math.sqrt(k * m))
    return (2.0 / omega_n) * (math.sqrt(1.0 + zeta**2) - zeta)


def sphere_mass(diameter_m: float, density_kg_m3: float) -> float:
    """Mass (kg) of a solid sphere of `diameter_m` (m) and `density_kg_m3` (kg/m^3)."""
    d = check_positive(diameter_m, "diameter_m")
    rho = check_positive(density_kg_m3, "density_kg_m3")
    return math.pi / 6.0 * d**3 * rho


# --- Table 3 consistency ----------------------------------------------------------------


@dataclass(frozen=True)
class TableRow:
    """One printed Table 3 row (fertilizer x surface) and what its numbers imply.

    Masses in kg, stiffness N/m, damping N s/m, time s. Fields can be read as attributes
    or as items (row["consistent"]); `as_dict()` gives a plain dict for JSON.
    """

    fertilizer: str
    surface: str
    restitution: float
    contact_time_s: float
    paper_stiffness_n_per_m: float
    paper_damping_ns_per_m: float
    mass_from_stiffness_kg: float
    mass_from_damping_kg: float
    stiffness_damping_mass_ratio: float
    """mass_from_stiffness / mass_from_damping (1 for self-consistent printed k and c)."""
    median_mass_kg: float
    """Median of all rows' stiffness-implied masses."""
    stiffness_mass_over_median: float
    sphere_mass_kg: float
    """Mass of a sphere of the fertilizer's median diameter (d50) and particle density."""
    stiffness_from_damping_mass_n_per_m: float
    """Eq. 8 stiffness recomputed from the damping-implied mass (compare to printed k)."""
    consistent: bool
    reasons: tuple[str, ...]

    def __getitem__(self, key: str) -> Any:
        if key not in self.__dataclass_fields__:
            raise KeyError(key)
        return getattr(self, key)

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["reasons"] = list(self.reasons)
        return out


def _factor(a: float, b: float) -> float:
    """How many times larger the larger of two positive numbers is (>= 1)."""
    return max(a, b) / min(a, b)


def paper_table_consistency(library: Optional[MaterialLibrary] = None) -> list[TableRow]:
    """Check every printed Table 3 row (pairs with paper_stiffness_n_per_m) for consistency.

    For each row the printed stiffness and damping are turned back into the granule mass
    they imply (with the printed restitution and impact time). A row is consistent unless
    its stiffness-implied mass is more than MEDIAN_MASS_FACTOR away from the median of all
    rows' stiffness-implied masses, or its stiffness- and damping-implied masses differ
    by more than STIFFNESS_DAMPING_MASS_FACTOR. Rows come in library order.
    """
    lib = library if library is not None else load_library()
    partial = []
    for name, fert in lib.fertilizers.items():
        for surface, k in fert.paper_stiffness_n_per_m.items():
            e = fert.pair("restitution", surface)
            t = fert.pair("impact_time_s", surface)
            c = fert.paper_damping_ns_per_m[surface]
            m_k = mass_from_stiffness(k, e, t)
            m_c = mass_from_damping(c, e, t)
            partial.append((name, fert, surface, e, t, float(k), float(c), m_k, m_c))
    if not partial:
        return []
    median = statistics.median(p[7] for p in partial)
    rows = []
    for name, fert, surface, e, t, k, c, m_k, m_c in partial:
        reasons = []
        if _factor(m_k, median) > MEDIAN_MASS_FACTOR:
            reasons.append(
                f"stiffness implies {m_k * 1e6:.1f} mg, {_factor(m_k, median):.1f}x away from "
                f"the median {median * 1e6:.1f} mg (limit {MEDIAN_MASS_FACTOR:g}x)"
            )
        if _factor(m_k, m_c) > STIFFNESS_DAMPING_MASS_FACTOR:
            reasons.append(
                f"stiffness implies {m_k * 1e6:.1f} mg but damping implies {m_c * 1e6:.1f} mg "
                f"({_factor(m_k, m_c):.1f}x, limit {STIFFNESS_DAMPING_MASS_FACTOR:g}x)"
            )
        rows.append(
            TableRow(
                fertilizer=name,
                surface=surface,
                restitution=e,
                contact_time_s=t,
                paper_stiffness_n_per_m=k,
                paper_damping_ns_per_m=c,
                mass_from_stiffness_kg=m_k,
                mass_from_damping_kg=m_c,
                stiffness_damping_mass_ratio=m_k / m_c,
                median_mass_kg=median,
                stiffness_mass_over_median=m_k / median,
                sphere_mass_kg=sphere_mass(fert.size.d50_m, fert.particle_density_kg_m3),
                stiffness_from_damping_mass_n_per_m=stiffness(m_c, e, t),
                consistent=not reasons,
                reasons=tuple(reasons),
            )
        )
    return rows


def paper_row_flagged(
    fertilizer: str, surface: str, library: Optional[MaterialLibrary] = None
) -> bool:
    """True when the pair's printed Table 3 row fails `paper_table_consistency`.

    Pairs without a printed row return False (there is nothing to flag); an unknown
    fertilizer or surface raises MaterialError.
    """
    lib = library if library is not None else load_library()
    lib.fertilizer(fertilizer)
    lib.check_surface(surface)
    for row in paper_table_consistency(lib):
        if row.fertilizer == fertilizer and row.surface == surface:
            return not row.consistent
    return False


def default_contact(
    fertilizer: str,
    surface: str,
    mass_kg: float,
    library: Optional[MaterialLibrary] = None,
) -> SpringDashpot:
    """Default spring-dashpot of a granule of `mass_kg` (kg) of `fertilizer` on `surface`.

    Computed from the pair's measured restitution and impact time (Table 3 inputs) with
    the given mass - never from the paper's printed stiffness or damping. A pair the paper
    did not measure raises MaterialError naming the pair. When the pair's printed row is
    flagged by `paper_table_consistency`, a PaperTableWarning is emitted: the printed k/c
    are not used, but the same row's measured e or t may be the faulty number.
    """
    lib = library if library is not None else load_library()
    fert = lib.fertilizer(fertilizer)
    lib.check_surface(surface)
    e = fert.pair("restitution", surface)
    t = fert.pair("impact_time_s", surface)
    result = spring_dashpot(mass_kg, e, t)
    if paper_row_flagged(fertilizer, surface, lib):
        warnings.warn(
            f"the paper's Table 3 row {fertilizer}/{surface} is flagged as inconsistent (its "
            "printed stiffness and damping do not fit its restitution and impact time at one "
            "plausible granule mass); the default uses the measured e and t with the given "
            "mass, but one of those may be the faulty number - set contact: in the scene "
            "if in doubt",
            PaperTableWarning,
            stacklevel=2,
        )
    return result
