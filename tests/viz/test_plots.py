"""Pictures of a simulation: files written, images not blank, odd results still drawn."""

import ast
import dataclasses
import inspect
import struct
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from spreadgym.config.scene import load_scene, scene_with
from spreadgym.physics.departure import RETAINED_TIMEOUT
from spreadgym.spread import pattern
from spreadgym.spread.pipeline import run_scene
from spreadgym.viz import plots

PLATE = {"x_m": 0.0, "y_m": -0.3, "angle_deg": 0.0, "length_m": 0.2, "material": "steel"}
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _run(scene):
    # Ask for granule paths where the pipeline can keep them; plots must work either way.
    extra = {"tracks": 10} if "tracks" in inspect.signature(run_scene).parameters else {}
    return run_scene(scene, model="pymunk", ci=False, **extra)


@pytest.fixture(scope="module")
def result():
    return _run(load_scene("paper", {"sim.granules": 200}))


@pytest.fixture(scope="module")
def deflected():
    scene = scene_with(load_scene("paper", {"sim.granules": 200}), {"deflectors": [PLATE]})
    return _run(scene)


def _png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == PNG_SIGNATURE, f"{path.name} is not a PNG"
    assert head[12:16] == b"IHDR"
    return struct.unpack(">II", head[16:24])


def _axes():
    fig = Figure(figsize=(7, 5), dpi=100)
    FigureCanvasAgg(fig)
    return fig, fig.add_subplot()


def test_write_simulation_plots(result, tmp_path):
    out = tmp_path / "new" / "plots"
    written = plots.write_simulation_plots(result, out)
    names = ["plan_view.png", "landing.png", "pattern.png", "cv_curve.png"]
    assert [p.name for p in written] == names
    for path in written:
        assert path.parent == out and path.is_file()
        width, height = _png_size(path)
        assert 600 <= width <= 800 and 400 <= height <= 600, (path.name, width, height)
        assert path.stat().st_size > 10_000, path.name  # something was drawn


def test_plan_view_draws_deflectors_and_bounced_rays(deflected):
    fig, ax = _axes()
    plots.plan_view(ax, deflected)
    fig.canvas.draw()
    (xa, ya), (xb, yb) = deflected.scene.deflectors[0].endpoints()
    plate_lines = [ln for ln in ax.get_lines()
                   if len(ln.get_xdata()) == 2 and np.allclose(ln.get_xydata(), [[xa, ya], [xb, yb]])]
    assert len(plate_lines) == 1 and plate_lines[0].get_linewidth() >= 3
    assert "deflector" in ax.get_title()

    # Rays that met the plate: the leg after the bounce runs along the launch velocity.
    launched = np.flatnonzero(deflected.launch.departed)
    rays = plots.departure_rays(deflected, launched, 0.6)
    bounced = [(i, r) for i, r in zip(launched, rays) if len(r) == 4]
    assert bounced, "the plate behind the disc should turn some granules"
    for i, ray in bounced:
        leg, v = ray[2] - ray[1], deflected.launch.velocity_m_s[i]
        assert leg @ v / (np.linalg.norm(leg) * np.linalg.norm(v)) > 0.999
        assert np.allclose(ray[0], deflected.departure.position_m[i])
        assert np.hypot(*ray[-1]) == pytest.approx(0.6)


def test_plan_view_without_tracks_draws_rays(result):
    bare = dataclasses.replace(result, departure=dataclasses.replace(result.departure, tracks=[]))
    if result.launch is result.departure:
        bare = dataclasses.replace(bare, launch=bare.departure)
    fig, ax = _axes()
    plots.plan_view(ax, bare, max_rays=40)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "flight direction" in labels and "path on the disc" not in labels
    reach = plots._view_radius_m(bare)
    ends = [np.hypot(*ln.get_xydata()[-1]) for ln in ax.get_lines() if len(ln.get_xdata()) >= 2]
    assert sum(np.isclose(e, reach) for e in ends) == 40
    fig.canvas.draw()


@pytest.mark.parametrize("driving", pattern.DRIVING)
@pytest.mark.parametrize("bout_width_m", [0.5, 1.5, 3.0, 3.5])
def test_overlapped_field_matches_bout_pattern(result, driving, bout_width_m):
    trays = result.trays
    n = pattern.bout_tray_count(bout_width_m, trays.width_m)
    k = np.arange(pattern.bout_columns(np.array([n]), driving == "racetrack")[0]) - n // 2  # a bout, or a period
    field = plots.overlapped_field(trays, bout_width_m, driving, k)
    np.testing.assert_allclose(field, pattern.bout_pattern(trays, bout_width_m, driving), rtol=1e-12)
    # Racetrack repeats every bout, back-and-forth every two.
    period = n if driving == "racetrack" else 2 * n
    np.testing.assert_allclose(plots.overlapped_field(trays, bout_width_m, driving, k + 3 * period), field,
                               rtol=1e-12)


def test_nothing_landed_still_draws(result, tmp_path):
    kept = dataclasses.replace(result.departure, outcome=np.full_like(result.departure.outcome, RETAINED_TIMEOUT),
                               tracks=[])
    empty = dataclasses.replace(
        result,
        departure=kept,
        launch=kept,
        landing=dataclasses.replace(result.landing, position_m=np.zeros((0, 2)), time_s=np.zeros(0)),
        trays=pattern.Trays(result.trays.center_m, np.zeros(result.trays.count), result.trays.width_m),
        metrics=dataclasses.replace(result.metrics, cv_percent_at_target=None, effective_swath_m=0.0,
                                    curve_bout_width_m=np.zeros(0), curve_cv_percent=np.zeros(0)),
    )
    assert len(plots.write_simulation_plots(empty, tmp_path)) == 4


def test_no_pyplot_global_state():
    tree = ast.parse(Path(plots.__file__).read_text())
    imported = [alias.name for node in ast.walk(tree) if isinstance(node, (ast.Import, ast.ImportFrom))
                for alias in node.names] + [node.module or "" for node in ast.walk(tree)
                                            if isinstance(node, ast.ImportFrom)]
    assert not any("pyplot" in name for name in imported)
    calls = [node.func.attr for node in ast.walk(tree)
             if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)]
    assert "use" not in calls and "rcParams" not in Path(plots.__file__).read_text()


def test_a_twin_machines_plan_view_draws_its_first_disc_in_its_frame():
    """The plan view of a twin machine is its first disc about that disc's axis: every path on the disc lies on the
    disc, every ray starts at its rim (simulate --plot and the web page alike; the paths were drawn in the machine
    frame, 0.4 m off the disc drawn at the origin; the page's test is tests/web/test_web_api.py's)."""
    scene = load_scene("twin-field", {"sim.granules": 256, "sim.angle_copies": 4})
    result = run_scene(scene, ci=False, tracks=10)
    radius = scene.spinner.radius_m
    centre, own, own_tracks = plots.first_disc(result)
    assert tuple(centre) == scene.disc_centres_m[0] and own_tracks == 10 and 2 * own == len(result.departure.position_m)
    fig, ax = _axes()
    plots.plan_view(ax, result)
    red = [ln.get_xydata() for ln in ax.get_lines() if ln.get_color() == plots.TRACK]
    assert len(red) == 10 and all(np.hypot(*path.T).max() <= radius * (1 + 1e-6) for path in red)
    rays = [ln.get_xydata() for ln in ax.get_lines() if ln.get_color() == plots.RAY]
    assert rays and all(np.hypot(*path[0]) == pytest.approx(radius, rel=1e-3) for path in rays)

