"""The compiled tray binning and copy turning against numpy's own arithmetic, bit for bit."""

import numpy as np
import pytest

from spreadgym.errors import ConfigError
from spreadgym.spread import pattern
from spreadgym.spread.estimate import replicate_tray_masses
from spreadgym.spread.rotations import turned_copies

W = 0.5


def numpy_binning(x, mass, replicate, replicates, w, half):
    """What collect and replicate_tray_masses computed before the kernel: floor, cast, two bincounts."""
    idx = np.floor(x / w + 0.5).astype(np.int64)
    m = max(int(np.max(np.abs(idx))) if idx.size else 0, int(np.ceil(half / w - 0.5 - 1e-9)))
    tray = idx + m
    pooled = np.bincount(tray, weights=mass, minlength=2 * m + 1)
    flat = replicate * (2 * m + 1) + tray
    per = np.bincount(flat, weights=mass, minlength=replicates * (2 * m + 1)).reshape(replicates, 2 * m + 1)
    return pooled, per, tray


@pytest.mark.parametrize("n, half", [(1, 0.0), (7, 0.0), (50_000, 0.0), (50_000, 40.0), (3, 12.0)])
def test_binning_is_bincounts_bits(n, half):
    rng = np.random.default_rng(n)
    x = rng.normal(1.5, 9.0, n)
    x[: n // 3] = np.round(x[: n // 3] / W - 0.5) * W + W / 2  # tray edges: the floor's boundary cases
    mass = rng.uniform(1e-6, 4e-5, n)
    replicate = rng.integers(0, 9, n)
    trays, per, index = pattern.collect_replicates(x, mass, replicate, 9, W, half)
    pooled_ref, per_ref, tray_ref = numpy_binning(x, mass, replicate, 9, W, half)
    assert trays.mass_kg.tobytes() == pooled_ref.tobytes()
    assert per.tobytes() == per_ref.tobytes()
    assert np.array_equal(index, tray_ref)
    assert replicate_tray_masses(x, mass, replicate, 9, W, half)[1].tobytes() == per_ref.tobytes()
    assert np.array_equal(pattern.collect_indexed(x, mass, W, half)[1], tray_ref)


def test_binning_errors_name_the_input():
    ok = np.zeros(3)
    for x, mass, replicate, key in [
        ([0.0, np.nan, 1.0], ok, [0, 0, 0], "x_m"),
        ([0.0, np.inf, 1.0], ok, [0, 0, 0], "x_m"),
        (ok, [1.0, -1e-9, 1.0], [0, 0, 0], "mass_kg"),
        (ok, [1.0, np.nan, 1.0], [0, 0, 0], "mass_kg"),
        (ok, ok, [0, 2, 0], "replicate"),
        (ok, ok, [0, -1, 0], "replicate"),
        ([0.0, 3000.0, 1e300], ok, [0, 0, 0], "pattern.tray_width_m"),
    ]:
        with pytest.raises(ConfigError) as e:
            pattern.collect_replicates(np.asarray(x, float), np.asarray(mass, float), np.asarray(replicate), 2, W)
        assert e.value.key == key
    with pytest.raises(ConfigError) as e:
        pattern.collect([0.0, 1e300], 1.0, W)
    assert e.value.key == "pattern.tray_width_m" and "allowed up to" in str(e.value)


@pytest.mark.parametrize("every", [True, False])
def test_turned_copies_are_numpys_turn(every):
    rng = np.random.default_rng(3)
    n, copies = 1000, 5
    angle = rng.uniform(-np.pi, np.pi, copies * n)
    cos, sin = np.cos(angle), np.sin(angle)
    landed = rng.normal(0.0, 10.0, (n, 2))
    mass = rng.uniform(1e-6, 1e-5, n)
    replicate = rng.integers(0, 8, n)
    rows = np.arange(copies * n) if every else np.flatnonzero(np.tile(rng.random(n) < 0.9, copies))
    x, m, r = np.empty(rows.size), np.empty(rows.size), np.empty(rows.size, dtype=replicate.dtype)
    turned_copies(every, np.zeros(0, np.int64) if every else rows, cos, sin, landed[:, 0], landed[:, 1], mass,
                  replicate, copies, x, m, r)
    j = rows % n
    assert x.tobytes() == (cos[rows] * landed[j, 0] - sin[rows] * landed[j, 1]).tobytes()
    assert m.tobytes() == (mass[j] / copies).tobytes()
    assert np.array_equal(r, replicate[j])
