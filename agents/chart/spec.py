"""What a chart is: the scene, the fertilizer x width cells and everything that decides
their results, checked before any work starts.

A cell's result depends only on the `ChartSpec` (never on the workers or the order the
cells run in): its seeds come from the base seed and the cell's key (`cell_seed`).
"""

from __future__ import annotations

import math
import zlib
from dataclasses import asdict, dataclass, field
from typing import Optional

import numpy as np

from spreadgym.agents.chart.variability import check_variability
from spreadgym.config.base import brief
from spreadgym.config.materials import MaterialLibrary, load_library
from spreadgym.config.resources import config_dir
from spreadgym.config.scene import Scene, bout_trays, check_pooled_work, load_scene, scene_from_dict, scene_with
from spreadgym.config.settings import SettingsSpace
from spreadgym.errors import ConfigError, MaterialError, SpreadgymError
from spreadgym.physics.contacts import runnable
from spreadgym.physics.selection import MODELS
from spreadgym.spread.pipeline import run_scene

SEARCH_MODEL = "auto"  # the fast default objective
VERIFY_MODEL = "pymunk"  # the full model every chart cell is verified with
VERIFY_RUNS = 8  # independent runs pooled for the verification (x the granules of one run)
PROBE_GRANULES = 256  # per probe of the reach check
PROBE_MODEL = "analytic"
MAX_PROBES = 32
MAX_BUDGET = 100_000  # simulations per cell: days of work already; beyond it only memory runs out
MAX_WIDTHS = 2000  # every multiple of the finest tray (0.05 m) up to 100 m
MAX_WIDTH_M = 100.0
MAX_STEADY_TOLERANCE_PP = 100.0  # a tolerance this wide ties every point of any chart cell
STEADY_TOLERANCE_PP = 2.0  # the default tie: within 2 SE of a cell's best plus 2 pp (its price: docs/charts.md)
TIE_PREFERENCES = ("lowest-rpm", "nearest")  # among tied points (sweep.py): the first is the default
# What a manifest without the field meant (charts made before the field): a manifest leaves a field out at this
# value, and an older chart folder or chart.json is read with it
MANIFEST_DEFAULTS = {"steady_tolerance_pp": 0.0, "tie_preference": "nearest", "materials": None}
READ_DEFAULTS = {**MANIFEST_DEFAULTS, "objective": "nominal"}  # a record without `objective` predates robust cells
OBJECTIVES = ("robust", "nominal")  # robust: the search minimises the variability model's quantile
METHODS = ("cmaes", "policy", "policy+search")


@dataclass(frozen=True)
class Cell:
    """One fertilizer at one working width."""

    fertilizer: str
    width_m: float

    @property
    def key(self) -> str:
        """File-name-safe and unique: the width in millimetres."""
        return f"{self.fertilizer}_{int(round(self.width_m * 1000)):06d}mm"


@dataclass(frozen=True)
class ChartSpec:
    """Everything a chart's rows depend on (the manifest of a chart folder)."""

    scene: dict  # the validated base scene, dumped (so a changed scene file is noticed)
    fertilizers: tuple[str, ...]
    widths_m: tuple[float, ...]
    driving: str
    budget: int
    granules: int  # per simulation, search and verification runs alike
    seed: int
    search_model: str = SEARCH_MODEL
    verify_model: str = VERIFY_MODEL
    verify_runs: int = VERIFY_RUNS
    settings: Optional[dict] = None  # keyword arguments of SettingsSpace beyond the scene (ranges)
    objective: str = "robust"
    method: str = "cmaes"
    policy: Optional[str] = None  # the policy file (method policy, policy+search)
    policy_sha256: Optional[str] = None  # its content, so a changed policy is noticed on resume
    variability: dict = field(default_factory=check_variability)  # the checked variability model
    steady_tolerance_pp: float = STEADY_TOLERANCE_PP  # the tie test: within 2 SE of the best plus this many pp
    tie_preference: str = TIE_PREFERENCES[0]  # which tied point a cell takes (sweep.py): lowest-rpm or nearest
    materials: Optional[dict] = None  # the chart fertilizers a user's materials file gave: {name: entry}

    @property
    def cells(self) -> list[Cell]:
        return [Cell(f, w) for f in self.fertilizers for w in self.widths_m]

    def previous(self, cell: Cell) -> Optional[Cell]:
        """The cell one width narrower in the same row (its settings start this cell's search), or
        None: the first width, or no search (`policy`: every cell stands alone)."""
        i = self.widths_m.index(cell.width_m)
        return Cell(cell.fertilizer, self.widths_m[i - 1]) if i > 0 and self.method != "policy" else None

    @property
    def draws(self) -> int:
        """Simulations per candidate: the variability model's draws (robust) or one (nominal)."""
        return self.variability["draws"] if self.objective == "robust" else 1

    @property
    def verify_simulations(self) -> int:
        """Full-model runs of a cell's verification: nominal and over the variability model."""
        return self.verify_runs + self.variability["verify_draws"] * self.variability["verify_runs_per_draw"]

    @property
    def max_simulations(self) -> int:
        """Most simulations a cell may make: the search's, the row repair's (per pass at most
        REPAIR_CANDIDATES candidates on at most the re-score budget's rounds, and one steady slice) and the
        verification's, twice when the row sweep moved the cell to another point (verified again)."""
        from spreadgym.agents.baselines import split_budget
        from spreadgym.agents.chart.sweep import REPAIR_CANDIDATES, REPAIR_PASSES, SLICE_POINTS, SLICE_REFINE

        axes = self.space(self.cell_scene(self.cells[0])).size
        per_pass = REPAIR_CANDIDATES * split_budget(self.budget)[1] + axes * (SLICE_POINTS + len(SLICE_REFINE))
        return (self.budget + REPAIR_PASSES * per_pass) * self.draws + 2 * self.verify_simulations

    @classmethod
    def from_manifest(cls, manifest: dict) -> "ChartSpec":
        """The spec a manifest (or chart.json's `spec`) records; a field it leaves out has its READ_DEFAULTS
        value (what charts made before the field did)."""
        fields = {**READ_DEFAULTS, "variability": check_variability(None), **manifest}
        return cls(**{k: tuple(v) if k in ("fertilizers", "widths_m") else v for k, v in fields.items()})

    def manifest(self) -> dict:
        """The spec as the chart folder and chart.json record it; a field of MANIFEST_DEFAULTS only away from
        that value, so a chart made before the field has the manifest it had (and resumes as it did)."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()
                if k not in MANIFEST_DEFAULTS or v != MANIFEST_DEFAULTS[k]}

    def base_scene(self) -> Scene:
        return scene_from_dict(self.scene)

    def library(self) -> MaterialLibrary:
        """The material library the cells run with, wherever they run (a cluster's workers included): the
        shipped one, the user's fertilizers the spec records, the base scene's inline fertilizer by its name."""
        return load_library(path=config_dir() / "materials.yaml").with_entries(self.materials or {}) \
            .with_inline(self.base_scene())

    def cell_scene(self, cell: Cell) -> Scene:
        """The base scene for one cell: its fertilizer, width, driving and granule count."""
        return scene_with(self.base_scene(), {"fertilizer": cell.fertilizer, "pattern.target_swath_m": cell.width_m,
                                              "pattern.driving": self.driving, "sim.granules": self.granules})

    def space(self, scene: Scene) -> SettingsSpace:
        return SettingsSpace(scene, **(self.settings or {}))


def cell_seed(base_seed: int, cell: Cell) -> np.random.SeedSequence:
    """The seed sequence of a cell: the base seed and the cell's key, nothing else."""
    return np.random.SeedSequence([int(base_seed), zlib.crc32(cell.key.encode("utf-8"))])


def parse_widths(text: str) -> tuple[float, ...]:
    """`W1,W2,...` or `LO:HI:STEP` (HI included when the steps reach it), in metres; at most
    `MAX_WIDTHS` widths, counted before any is built."""
    text = text.strip()
    sep = ":" if ":" in text else ","
    if text.count(sep) >= MAX_WIDTHS:
        raise SpreadgymError(f"--widths: {text.count(sep) + 1} widths given; allowed: at most {MAX_WIDTHS}")
    try:
        parts = [float(p) for p in text.split(sep)]
    except ValueError:
        parts = []
    if not parts or (sep == ":" and len(parts) != 3):
        raise SpreadgymError(f"--widths {brief(text)}: expected W1,W2,... or LO:HI:STEP in metres")
    if sep == ":":
        lo, hi, step = parts
        if not all(math.isfinite(v) for v in parts) or step <= 0 or hi < lo:
            raise SpreadgymError(f"--widths {text}: LO:HI:STEP needs LO <= HI and STEP > 0")
        count = math.floor((hi - lo) / step + 1e-9) + 1
        if count > MAX_WIDTHS:
            raise SpreadgymError(f"--widths {text}: {count:g} widths; allowed: at most {MAX_WIDTHS} "
                                 "(a larger STEP or a shorter range)")
        widths = [round(lo + i * step, 9) for i in range(count)]
    else:
        widths = parts
    return tuple(dict.fromkeys(widths))


def check_widths(widths_m: tuple[float, ...], tray_width_m: float) -> None:
    """Each width in (0, 100] m, on the tray grid and at least two trays, and one cell file
    per width (no two widths that agree to the millimetre of the cell key)."""
    if len(widths_m) > MAX_WIDTHS:
        raise SpreadgymError(f"--widths: {len(widths_m)} widths; allowed: at most {MAX_WIDTHS}")
    keys: dict[str, float] = {}
    for w in widths_m:
        if not (math.isfinite(w) and 0.0 < w <= MAX_WIDTH_M):
            raise SpreadgymError(f"--widths: {w:g} m is out of range; allowed (0, {MAX_WIDTH_M:g}] m")
        try:
            bout_trays(w, tray_width_m)
        except ValueError as exc:
            raise SpreadgymError(f"--widths: {exc}") from None
        key = Cell("", w).key
        if key in keys:
            raise SpreadgymError(f"--widths: {keys[key]!r} m and {w!r} m are one width to the millimetre (one "
                                 "cell file); give each width once")
        keys[key] = w


def resolve_fertilizers(text_or_names, scene: Scene, library: MaterialLibrary) -> tuple[tuple[str, ...], list[str]]:
    """(fertilizers, notes). `all` is every library fertilizer whose surface pairs on this
    scene are measured or set by the scene; a named one must be, or it is an error."""
    names = text_or_names.split(",") if isinstance(text_or_names, str) else list(text_or_names)
    names = [n.strip() for n in names if n.strip()]
    if not names:
        raise SpreadgymError("--fertilizers: give at least one fertilizer or 'all'")
    if "all" in names and names != ["all"]:
        raise SpreadgymError("--fertilizers: 'all' stands alone (every fertilizer with measured pairs on the "
                             "scene); give all, or names without it")
    notes = []
    if names == ["all"]:
        chosen = []
        for name in library.fertilizers:
            try:
                runnable(scene_with(scene, {"fertilizer": name}), library)
                chosen.append(name)
            except MaterialError as exc:
                notes.append(f"{name} left out: {exc}")
        if not chosen:
            raise SpreadgymError(f"--fertilizers all: no fertilizer has measured pairs on this scene ({notes[0]})")
        return tuple(chosen), notes
    for name in names:
        if name not in library.fertilizers:
            known = ", ".join(library.fertilizers)
            raise SpreadgymError(f"--fertilizers: unknown fertilizer {brief(name)}; known: {known} (or all alone)")
        try:
            runnable(scene_with(scene, {"fertilizer": name}), library)
        except MaterialError as exc:
            raise SpreadgymError(f"--fertilizers {name}: {exc}") from None
    return tuple(dict.fromkeys(names)), notes


def make_spec(scene: str, fertilizers, widths, driving: Optional[str] = None, budget: int = 200,
              granules: Optional[int] = None, seed: int = 0, search_model: str = SEARCH_MODEL,
              verify_model: str = VERIFY_MODEL, verify_runs: int = VERIFY_RUNS, settings: Optional[dict] = None,
              objective: str = "robust", method: str = "cmaes", policy: Optional[str] = None, variability=None,
              library: Optional[MaterialLibrary] = None, steady_tolerance_pp: float = STEADY_TOLERANCE_PP,
              tie_preference: str = TIE_PREFERENCES[0]) -> tuple[ChartSpec, list[str]]:
    """A checked ChartSpec and notes for people. Every problem is a SpreadgymError naming
    the flag or key: unknown fertilizer or model, width off the tray grid or beyond what
    the scene can throw, budget or granules below 1, settings ranges out of bounds, an
    unknown objective or method, a steady tolerance not a number in [0, 100] pp, a policy
    given without a policy method or missing where the scene has no shipped one
    (`policy.shipped_policy`), a variability entry out of range."""
    if objective not in OBJECTIVES:
        raise SpreadgymError(f"--objective: {brief(objective)}; allowed: {', '.join(OBJECTIVES)}")
    if method not in METHODS:
        raise SpreadgymError(f"--method: {brief(method)}; allowed: {', '.join(METHODS)}")
    if policy is not None and not method.startswith("policy"):
        raise SpreadgymError(f"--policy: not used by --method {method}")
    variability = check_variability(variability)
    steady_tolerance_pp = check_steady_tolerance(steady_tolerance_pp)
    if tie_preference not in TIE_PREFERENCES:
        raise SpreadgymError(f"tie preference: {brief(tie_preference)}; allowed: {', '.join(TIE_PREFERENCES)}")
    base = load_scene(scene)
    library = (library or load_library()).with_inline(base)  # the scene's own fertilizer is a chart fertilizer too
    if not 1 <= int(budget) <= MAX_BUDGET:
        raise SpreadgymError(f"--budget: {budget} is out of range; allowed [1, {MAX_BUDGET}] simulations")
    if int(seed) < 0:
        raise SpreadgymError(f"--seed: {seed} must be >= 0")
    granules = base.sim.granules if granules is None else int(granules)
    if not 1 <= granules <= 1_000_000:
        raise SpreadgymError(f"--granules: {granules} is out of range; allowed [1, 1000000]")
    for flag, model in (("search model", search_model), ("verification model", verify_model)):
        if model not in MODELS:
            raise SpreadgymError(f"{flag}: unknown model {brief(model)}; allowed: {', '.join(MODELS)}")
    if int(verify_runs) < 2:
        raise SpreadgymError(f"verification runs: {verify_runs} must be at least 2")
    driving = driving or base.pattern.driving
    if driving not in ("racetrack", "back-and-forth"):
        raise SpreadgymError(f"--driving: {brief(driving)}; allowed: racetrack, back-and-forth")
    names, notes = resolve_fertilizers(fertilizers, base, library)
    widths_m = parse_widths(widths) if isinstance(widths, str) else tuple(dict.fromkeys(float(w) for w in widths))
    if not widths_m:
        raise SpreadgymError("--widths: give at least one width")
    check_widths(widths_m, base.pattern.tray_width_m)
    digest = None
    if method.startswith("policy"):
        from spreadgym.agents.chart.policy import check_policy, shipped_policy

        policy, digest = check_policy(shipped_policy(base, method) if policy is None else policy, base)
        names, notes = _policy_fertilizers(names, notes, fertilizers, policy, digest)
    spec = ChartSpec(base.model_dump(mode="json"), names, tuple(sorted(widths_m)), driving, int(budget), granules,
                     int(seed), search_model, verify_model, int(verify_runs), settings, objective, method, policy,
                     digest, variability, steady_tolerance_pp, tie_preference,
                     {n: library.user_entries[n] for n in names if n in library.user_entries} or None)
    try:
        scene = spec.cell_scene(spec.cells[0])
        check_pooled_work(scene, spec.verify_runs, "--granules")
        check_pooled_work(scene, variability["verify_runs_per_draw"], "variability.verify_runs_per_draw")
    except ConfigError as exc:
        if exc.key == "sim.granules":
            raise SpreadgymError(f"--granules: {exc.message}") from None
        raise
    space = spec.space(spec.cell_scene(spec.cells[0]))
    for name in names:
        reach = widest_pattern_m(spec, space, name, library)
        too_wide = [w for w in spec.widths_m if w > reach]
        if too_wide:
            raise SpreadgymError(f"--widths: {too_wide[0]:g} m is beyond what the scene can throw {name}: the widest "
                                 f"single-pass pattern within the settings' ranges is {reach:g} m")
    return spec, notes


def _policy_fertilizers(names, notes, requested, policy, digest) -> tuple[tuple[str, ...], list[str]]:
    """The fertilizers a policy method can chart: `all` keeps those the policy was trained
    on (the others noted); a named one it does not know is an error naming it."""
    from spreadgym.agents.chart.policy import policy_fertilizers

    known = policy_fertilizers(policy, digest)
    unknown = [name for name in names if name not in known]
    if unknown and requested not in ("all", ["all"], ("all",)):
        raise SpreadgymError(f"--fertilizers {unknown[0]}: the policy {policy} was trained without it (it knows "
                             f"{', '.join(known)}); chart it with --method cmaes")
    notes = notes + [f"{name} left out: the policy was trained without it" for name in unknown]
    return tuple(name for name in names if name in known), notes


def check_steady_tolerance(value) -> float:
    """`--steady-tolerance-pp`: a finite number of percentage points in [0, MAX_STEADY_TOLERANCE_PP]."""
    try:
        number = float(value) if not isinstance(value, (bool, str)) else float("nan")
    except (TypeError, ValueError):
        number = float("nan")
    if not (math.isfinite(number) and 0.0 <= number <= MAX_STEADY_TOLERANCE_PP):
        raise SpreadgymError(f"--steady-tolerance-pp: {brief(value)} is not allowed; allowed: a number in "
                             f"[0, {MAX_STEADY_TOLERANCE_PP:g}] percentage points")
    return number


def widest_pattern_m(spec: ChartSpec, space: SettingsSpace, fertilizer: str, library: MaterialLibrary) -> float:
    """The widest single-pass pattern (m, edge to edge of the loaded trays) at the top disc
    speed over the corners of the other settings, on the fast closed-form model.

    Passes at a bout width beyond this leave bare ground between them whatever the
    settings: no chart cell there can be even."""
    scene = scene_with(spec.cell_scene(Cell(fertilizer, spec.widths_m[0])),
                       {"sim.granules": PROBE_GRANULES, "sim.seed": spec.seed})
    others = space.size - 1
    corners = np.array(np.meshgrid(*([[-1.0, 1.0]] * others), indexing="ij")).reshape(others, -1).T
    step = max(1, int(math.ceil(len(corners) / MAX_PROBES)))
    widest = 0.0
    for corner in corners[::step]:
        probe = space.apply(scene, np.concatenate([[1.0], corner]))
        widest = max(widest, run_scene(probe, model=PROBE_MODEL, library=library, ci=False).trays.pattern_width_m)
    return widest

