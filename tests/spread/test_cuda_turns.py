"""The copies' turns on a CUDA GPU (spreadgym.spread.cuda_turns) under numba's CUDA
simulator, against the CPU's `von_mises.antithetic_turns` design by design and against
the launch's CPU twin `von_mises.flat_turns`: every cosine and sine to the
bit (the simulator runs the CPU's scalar code; a real GPU's cosine and logarithm may
differ in the last bits). The whole finish with GPU turns is held to the CPU's by
tests/physics/test_cuda_spinner.py and tests/envs/test_env_device.py."""

DRAWN = """
import json, numpy as np
from spreadgym.physics.compiled import pcg64
from spreadgym.spread import cuda_turns, von_mises

rng = np.random.default_rng(3)
# designs: (granules, copies, run boundaries within the design); the third has no runs here
designs = [(13, 8, [0, 5, 13]), (9, 7, [0, 9]), (6, 4, []), (11, 2, [0, 4, 6, 11])]
kappas = np.array([1e-9, 3e-6, 2e-3, 0.3, 4.0, 37.0, 900.0, 5e5])  # every branch the kernel draws
counts = [n for n, _, _ in designs]
first = np.concatenate([[0], np.cumsum(counts)])
copies = np.array([k for _, k, _ in designs])
turn_first = np.concatenate([[0], np.cumsum(copies * counts)])
kappa = rng.choice(kappas, first[-1])
mu = rng.uniform(-np.pi, np.pi, first[-1])
run_design, run_start, run_stop, seeds = [], [], [], []
for d, (_, _, bounds) in enumerate(designs):
    for a, b in zip(bounds[:-1], bounds[1:]):
        run_design.append(d); run_start.append(a); run_stop.append(b); seeds.append((d, a, 7))
run_design, run_start, run_stop = (np.array(v, dtype=np.int64) for v in (run_design, run_start, run_stop))
states = pcg64.seeded(seeds)
given = (states, run_design, run_start, run_stop, first, copies, turn_first, kappa, np.cos(mu), np.sin(mu))
cos, sin = cuda_turns.draw_turns(*given)
twin_cos, twin_sin = von_mises.flat_turns(*given)  # the CPU's twin of the launch
kept = bool(np.array_equal(states, pcg64.seeded(seeds)))  # both leave the host's states as they are
rows = []
for d, (n, k, bounds) in enumerate(designs):
    if not bounds:
        continue
    mine = run_design == d
    a, b = first[d], first[d + 1]
    cpu_cos, cpu_sin = np.full((k, n), np.nan), np.full((k, n), np.nan)
    von_mises.antithetic_turns(pcg64.seeded([s for s, m in zip(seeds, mine) if m]), run_start[mine], run_stop[mine],
                               kappa[a:b], np.cos(mu[a:b]), np.sin(mu[a:b]), cpu_cos, cpu_sin)
    gpu_cos = cos[turn_first[d]:turn_first[d + 1]].reshape(k, n)
    gpu_sin = sin[turn_first[d]:turn_first[d + 1]].reshape(k, n)
    twin = slice(turn_first[d] + n, turn_first[d + 1])  # rows 1..
    rows.append({"design": d, "cos_equal": bool(np.array_equal(gpu_cos[1:], cpu_cos[1:])),
                 "sin_equal": bool(np.array_equal(gpu_sin[1:], cpu_sin[1:])),
                 "twin_equal": bool(np.array_equal(cos[twin], twin_cos[twin])
                                    and np.array_equal(sin[twin], twin_sin[twin])),
                 "unit": float(np.abs(gpu_cos[1:]**2 + gpu_sin[1:]**2 - 1).max()),
                 "distinct": int(np.unique(gpu_cos[1:]).size)})
none = cuda_turns.draw_turns(np.empty((0, 6), dtype=np.uint64), run_design[:0], run_start[:0], run_stop[:0], first,
                             copies, turn_first, kappa, mu, mu)
print(json.dumps({"rows": rows, "size": int(cos.size), "empty": [a.size for a in none], "states_kept": kept}))
"""


def test_the_gpu_draws_every_run_s_turns_as_the_cpu_does(cuda_simulator):
    found = cuda_simulator(DRAWN)
    assert [row["design"] for row in found["rows"]] == [0, 1, 3]
    for row in found["rows"]:
        assert row["cos_equal"] and row["sin_equal"] and row["twin_equal"], row
        assert row["unit"] < 1e-15 and row["distinct"] > 5, row  # real turns, not a constant
    assert found["size"] == 13 * 8 + 9 * 7 + 6 * 4 + 11 * 2
    assert found["empty"] == [found["size"]] * 2  # no runs: nothing launched, the blocks returned unwritten
    assert found["states_kept"]
