"""The batch finish of plain designs (spread.plain_finish, spread.finish_kernel): the same
bits as `pipeline.finish_scene`, design by design, in every case it takes and in the
cases it hands back."""

import numpy as np
import pytest
from test_batch import _same

from spreadgym import threads
from spreadgym.config.scene import MAX_RPM, load_scene
from spreadgym.errors import ConfigError
from spreadgym.physics.selection import SPINNER_MODELS
from spreadgym.spread import pattern, rotations
from spreadgym.spread.batch import run_batch
from spreadgym.spread.pipeline import finish_scene, plan_scene, run_scene
from spreadgym.spread.plain_finish import finish_plain, is_plain
from spreadgym.spread.von_mises import LARGE_KAPPA


def _finished_both_ways(scenes, library):
    plans = [plan_scene(scene, "auto", library) for scene in scenes]
    departures = [SPINNER_MODELS[plan.chosen].run_batch(plan.spinner_runs()) for plan in plans]
    return finish_plain(plans, departures), [finish_scene(p, d) for p, d in zip(plans, departures)]


@pytest.mark.parametrize("count", [1, 2])
def test_plain_designs_finish_as_finish_scene_does_bit_for_bit(library, monkeypatch, count):
    monkeypatch.setenv(threads.ENV_VAR, str(count))
    small = {"sim.granules": 384}
    settings = [
        {}, {"spinner.cone_deg": 8.0}, {"flight.magnus": True}, {"vanes.pitch_deg": 15.0, "sim.angle_copies": 7},
        {"sim.replicates": 2}, {"sim.replicates": 1}, {"fertilizer": "potassium-chloride"},
        {"pattern.driving": "back-and-forth"}, {"pattern.tray_width_m": 0.3, "pattern.target_swath_m": 24.0},
        {"spinner.rpm": 150.0}, {"spinner.rpm": 10.0}, {"flight.drag_coefficient": 0.0},  # rpm 10: none departs
    ]
    scenes = [load_scene("paper", {**small, "sim.seed": i, **extra}) for i, extra in enumerate(settings)]
    scenes.append(load_scene("field", {**small, "sim.seed": 40}))
    assert all(is_plain(plan_scene(s, "auto", library)) for s in scenes)
    for new, old in zip(*_finished_both_ways(scenes, library)):
        _same(new, old)


def test_a_design_it_cannot_take_goes_through_finish_scene(library):
    # a feed spot of 0.02 mm: concentrations above 1e6, whose turns numpy draws itself
    tiny = load_scene("paper", {"sim.granules": 256, "feed.spread_m": 0.00002})
    plan = plan_scene(tiny, "auto", library)
    granules = plan.spins[0][0]
    assert rotations.TurnLaws.of(granules.release_xy_m, [tiny], [granules.count]).kappa.max() > LARGE_KAPPA
    plain = load_scene("paper", {"sim.granules": 256})
    for new, old in zip(*_finished_both_ways([plain, tiny, plain], library)):
        _same(new, old)


def test_an_error_of_the_trays_is_the_single_runs(library):
    wide = load_scene("paper", {"sim.granules": 128, "pattern.tray_width_m": 0.05, "pattern.target_swath_m": 24.0,
                                "spinner.rpm": MAX_RPM, "spinner.height_m": 5.0, "flight.drag_coefficient": 0.0})
    with pytest.raises(ConfigError) as single:
        run_scene(wide, library=library)
    with pytest.raises(ConfigError) as batch:
        run_batch([load_scene("paper", {"sim.granules": 128}), wide], library=library)
    assert str(batch.value) == str(single.value) and "allowed up to" in str(batch.value)


def test_only_plain_designs_are_plain(library):
    assert is_plain(plan_scene(load_scene("paper"), "auto", library))
    for name, extra in [("twin-field", {}), ("paper-deflectors", {}), ("paper", {"sim.angle_copies": 1}),
                        ("field", {"flight.wind_m_s": [2.0, 0.0], "pattern.driving": "racetrack"}),
                        ("paper", {"feed.spread_m": 0.0})]:
        assert not is_plain(plan_scene(load_scene(name, extra), "auto", library)), name


def _fold_pairs_in_numpy(tray_count, counts, driving):
    """`pattern.fold_pairs` as numpy computed it before it was compiled: the order
    `bout_cvs` has always added the pairs in (bout by bout, tray by tray; back-and-forth:
    unmirrored passes, then mirrored; an even back-and-forth bout as its 2n-tray period)."""
    m = tray_count // 2
    i = np.arange(-m, m + 1)[None, :]
    n = np.asarray(counts, dtype=np.int64)[:, None]
    trays = np.broadcast_to(np.arange(tray_count), (n.shape[0], tray_count))
    if driving == "racetrack":
        start = np.cumsum(n) - n[:, 0]
        return trays.ravel(), (start[:, None] + (i + n // 2) % n).ravel()
    columns = np.where(n % 2 == 0, 2 * n, n)
    start = np.cumsum(columns) - columns[:, 0]
    q = np.concatenate([(i + n // 2) % (2 * n), (n - i + n // 2) % (2 * n)], axis=1)
    hit = q < columns
    return np.concatenate([trays, trays], axis=1)[hit], (start[:, None] + q)[hit]


@pytest.mark.parametrize("driving", ["racetrack", "back-and-forth"])
def test_the_compiled_fold_pairs_keep_numpys_order(driving):
    rng = np.random.default_rng(3)
    for _ in range(60):
        trays = 2 * int(rng.integers(0, 40)) + 1
        counts = rng.integers(1, 2 * trays + 3, size=int(rng.integers(1, 6)))
        tray, column = pattern.fold_pairs(trays, counts, driving)
        want_tray, want_column = _fold_pairs_in_numpy(trays, counts, driving)
        assert np.array_equal(tray, want_tray) and np.array_equal(column, want_column)


def test_the_curve_widths_are_one_to_top_trays_for_any_tray_width():
    """The kernel takes the curve's bouts as 1..2r+1 trays; `default_widths_m` rounds the
    widths to the nanometre and `bout_tray_counts` turns them back: the same counts, for
    tray widths of any decimals across the allowed range and the widest rows."""
    rng = np.random.default_rng(5)
    for width in [0.05, 0.1, 0.3, 0.5, 1.0 / 3.0, 0.123456789123, 5.0, *rng.uniform(0.05, 5.0, 40)]:
        top = min(pattern.MAX_TRAYS, int(200.0 / width))
        widths = np.round(np.arange(1, top + 1) * width, 9)
        assert np.array_equal(pattern.bout_tray_counts(widths, width), np.arange(1, top + 1)), width
