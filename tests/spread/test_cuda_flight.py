"""The flight on a CUDA GPU (spreadgym.spread.cuda_flight) under numba's CUDA simulator,
against the CPU kernel: every landing point and time to the bit (the simulator runs the
CPU's scalar code; a real GPU may differ in the last bits where it fuses multiply-adds)."""

FLOWN = """
import json, numpy as np
from spreadgym.config.scene import load_scene
from spreadgym.spread import flight
from spreadgym.spread.flight_kernel import LANES

rng = np.random.default_rng(7)
n = LANES + 5  # a whole thread and a part-filled last one
position = rng.normal(size=(n, 2)) * 0.1
velocity = np.c_[rng.normal(size=(n, 2)) * 15.0, rng.normal(size=n) * 2.0]
height = np.abs(rng.normal(size=n)) + 0.5
height[[0, LANES + 2]] = 0.0  # on the ground at launch: land at once where they are
diameter = rng.uniform(2e-3, 4e-3, n)
spin = rng.normal(size=n) * 300.0
base = load_scene("paper").flight
cases = (("drag, adaptive", {}, None), ("drag, fixed-step RK4", {}, 2e-3),
         ("Magnus lift and wind", {"magnus": True, "wind_m_s": (1.5, -0.5)}, None))
flown = {(name, device): flight.fly(position, height, velocity, diameter, 1734.0, base.model_copy(update=update),
                                    dt_s=dt, spin_rad_s=spin, device=device)
         for device in ("cuda", "cpu") for name, update, dt in cases}  # the GPU's first: no output row left over
rows = []
for name, _, _ in cases:
    cpu, gpu = flown[name, "cpu"], flown[name, "cuda"]
    rows.append({"case": name, "xy_equal": bool(np.array_equal(cpu.position_m, gpu.position_m)),
                 "t_equal": bool(np.array_equal(cpu.time_s, gpu.time_s)),
                 "moved": bool(np.all(cpu.time_s[height > 0] > 0)),
                 "grounded_stay": bool(np.array_equal(gpu.position_m[height == 0], position[height == 0]))})
print(json.dumps({"rows": rows}))
"""


def test_the_gpu_flight_lands_every_granule_where_the_cpu_does(cuda_simulator):
    found = cuda_simulator(FLOWN)
    assert [row["case"] for row in found["rows"]] == ["drag, adaptive", "drag, fixed-step RK4", "Magnus lift and wind"]
    for row in found["rows"]:
        assert row["xy_equal"] and row["t_equal"], row
        assert row["moved"] and row["grounded_stay"], row

