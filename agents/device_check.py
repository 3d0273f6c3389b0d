"""One measuring run for a lent 16-core machine with an NVIDIA GPU (the device tool's
`nvidia-h100-x1` / `nvidia-h200`): CPU scaling of the batch paths and the CUDA spinner
against the CPU, in one call of a few minutes. Run through `agents/device_check.sh`,
which installs the carried wheels and this repository into a folder first (a new temporary
one, or `SITE`, kept for a second call on the same machine) and, with `MPS=1`, runs this
under NVIDIA's Multi-Process Service; never run by the tests or `make bench`.

What it measures (every figure is written under `--out` as soon as it exists, so a run
cut short still returns what it did; with `--contention`, only 1 and then
agents/contention.py's probe at the `--threads` counts, nothing beside it):

1. versions and the machine (env.json): python, numpy, numba, numba-cuda, cores, GPU, MPS.
2. (not with `--gpu-only`) CPU scaling at 1, 2, 4, 8, 16 threads (`spreadgym.threads.set_threads`), median of
   `--repeats` timed blocks after a warm-up block, the two series' blocks interleaved
   (cpu_scaling.csv, the columns of docs/bench/batch-16-cores-scaling.csv):
   (a) `run_batch` of `--batch` mixed paper / field / twin-field scenes, built as
       `studies.benchmarks.batch_series` builds them except that the rpm cycles through
       its 64-design range (450-765 rpm): its formula reaches 1725 rpm at 256 designs,
       outside the compiled model's validated envelope, where "auto" runs pymunk;
   (b) the native SpinnerDesign vector env (`gym.make_vec(..., autoreset_mode="same_step")`)
       with `--batch` sub-envs;
   (c) above one thread, that vector env in as many worker processes as threads, one
       thread each (`workers`);
   checking that tray masses (a) and rewards and observations (b, c) are bit-identical to
   the one-thread run's. Where the vector env refuses more than 61 sub-envs of the default
   2048-granule, 32-copy scene (`config.scene.MAX_GRANULE_COPIES`, a memory guard, in the
   code before its steps ran in parts), this process raises that guard for the benchmark
   only (256 sub-envs in one batch held 2.2 GB here), and env.json says so.
   After each thread count's blocks, the stages of `run_batch` on `--batch` paper designs
   (plan / spinner / finish, timed by wrappers around the calls run_batch makes, so the
   run_batch of the tree as it is: `stage_timers`; cpu_stages.csv).
3. The GPU, in a second process started at once (`--role gpu`), so that numba's CUDA
   compile of the spinner kernel (minutes on a slow core, single-threaded) overlaps the
   CPU work. The CPU series up to 8 threads run while it compiles (one core of 16 busy);
   the 16-thread series wait for the compile to end first (at most `--compile-wait-s`;
   each row says whether the compile was still running), and the GPU process waits for
   the CPU series to end before it times anything, so no other timing shares the machine
   with the other process's work. Then (gpu.json, gpu_spinner.csv, gpu_batch.csv):
   - CPU against GPU on one batch (paper at 2048 granules, varied rpm and seeds, plus
     twin-field and field scenes): outcome counts per design, tray masses, CV at the
     target, departure speeds;
   - the vector env with device "cuda" in one process and in 16 worker processes sharing
     the GPU (one thread each; rewards compared to the one-process GPU run's), and with
     "cpu" (16 threads); then the whole `run_batch` on "cuda" and "cpu";
   - the spinner kernel alone under three schedules (the shipped queue of granules handed
     out longest first, the queue in launch order, one granule per thread), at 1024 and
     4096 designs, their outputs compared to the bit;
   - the spinner stage alone (`model.simulate_compiled_batch`, host<->device copies
     included) on the GPU and on the CPU at 1 and 16 threads, 64-4096 paper designs (512
     planned designs repeated in turn; a CPU call guessed over 20 s is skipped), with the
     call's three steps timed once apart.
   In that order: what is least known first, so a run cut short keeps it.

Every section is guarded (its error is one printed line), capped in time, and the whole
run keeps to `--deadline-s` from its start (the CPU sections leave `--gpu-reserve-s` of
it to the GPU). Without a GPU the GPU section says so and stops. `--quick` shrinks the CPU
sections for a dry run on a small machine (24 designs, two thread counts); `--gpu-sim`
runs the GPU section on numba's CUDA simulator at toy sizes (a check of this script, not
a timing). Seven files come back: env.json, cpu_scaling.csv, cpu_stages.csv, gpu.json,
gpu_spinner.csv, gpu_batch.csv and the shell script's device_check.log.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import traceback
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Callable, Optional

import numpy as np

FULL_THREADS = (1, 2, 4, 8, 16)
RPM_CYCLE = 64  # the mixed scenes' rpm: 450 + 5 (i mod 64), batch_series' range at 64 designs


# ----------------------------------------------------------------------------- plumbing

class Clock:
    """Seconds since the run's start (shared by both processes) and what is left of its deadline."""

    def __init__(self, t0: float, deadline_s: float):
        self.t0, self.deadline_s = t0, deadline_s

    def elapsed(self) -> float:
        return time.time() - self.t0

    def left(self) -> float:
        return self.deadline_s - self.elapsed()


CLOCK = Clock(time.time(), 420.0)
TAG = "[cpu]"


def say(message: str) -> None:
    print(f"{TAG} {CLOCK.elapsed():6.1f}s  {message}", flush=True)


@contextmanager
def section(name: str, cap_s: float):
    """A guarded section: prints its start and end with elapsed seconds; an error is one line."""
    started = time.time()
    say(f"== {name} (cap {cap_s:.0f} s, {CLOCK.left():.0f} s left in the run)")
    try:
        yield min(started + cap_s, CLOCK.t0 + CLOCK.deadline_s - 5.0)
    except Exception as error:  # noqa: BLE001 (one line per failed section, the run goes on)
        last = traceback.extract_tb(error.__traceback__)[-1]
        say(f"!! {name} failed: {type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''} "
            f"({Path(last.filename).name}:{last.lineno})")
    finally:
        say(f"== {name} done in {time.time() - started:.1f} s")


class Table:
    """A CSV file rewritten whole after every row, so a cut run keeps what it measured."""

    def __init__(self, path: Path):
        self.path, self.rows = path, []

    def add(self, row: dict) -> None:
        self.rows.append(row)
        fields = list(dict.fromkeys(k for r in self.rows for k in r))
        with open(self.path, "w", newline="") as f:
            writer = csv.DictWriter(f, fields)
            writer.writeheader()
            writer.writerows(self.rows)


def write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=1, default=str))


def guarded(name: str, work: Callable, *args) -> None:
    """work(*args), an error printed as one line instead of raised."""
    try:
        work(*args)
    except Exception as error:  # noqa: BLE001
        say(f"!! {name} failed: {type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}")


def timed(run: Callable[[], object], repeats: int, until: float, warm: bool = True,
          sync: Callable[[], None] = lambda: None) -> tuple[list[float], object]:
    """Wall times of up to `repeats` calls of `run` (after one untimed call when `warm`),
    stopping before a call that would end past time.time() `until`, judged by the last
    one (at least one timed call); and the last result."""
    result = None
    if warm:
        result = run()
        sync()
    times: list[float] = []
    for _ in range(repeats):
        if times and time.time() + times[-1] > until:
            break
        start = time.perf_counter()
        result = run()
        sync()
        times.append(time.perf_counter() - start)
    return times, result


def spread_of(values: list[float]) -> tuple[float, float, float]:
    return statistics.median(values), min(values), max(values)


def wait_for(path: Path, until: float, what: str) -> bool:
    """Poll for `path` until time.time() passes `until`; True when it appeared."""
    announced = False
    while not path.exists():
        if time.time() > until:
            say(f"gave up waiting for {what}")
            return False
        if not announced:
            say(f"waiting for {what}")
            announced = True
        time.sleep(0.5)
    return True


# ----------------------------------------------------------------------------- scenes

def mixed_scenes(count: int, granules: Optional[int] = None):
    """batch_series' paper / field / twin-field scenes (seed i), rpm cycling 450-765."""
    from spreadgym.config.scene import load_scene, scene_with

    extra = {} if granules is None else {"sim.granules": granules}
    bases = [load_scene(name, extra) for name in ("paper", "field", "twin-field")]
    return [scene_with(bases[i % 3], {"sim.seed": i, "spinner.rpm": 450.0 + 5.0 * (i % RPM_CYCLE)})
            for i in range(count)]


def paper_designs(count: int, granules: Optional[int] = None, seed0: int = 0):
    """Paper designs, seed seed0 + i, rpm 400-1030 in 10 rpm steps (the validated envelope)."""
    from spreadgym.config.scene import load_scene, scene_with

    base = load_scene("paper", {} if granules is None else {"sim.granules": granules})
    return [scene_with(base, {"sim.seed": seed0 + i, "spinner.rpm": 400.0 + 10.0 * (i % 64)}) for i in range(count)]


def others(name: str, count: int, granules: Optional[int] = None):
    from spreadgym.config.scene import load_scene, scene_with

    base = load_scene(name, {} if granules is None else {"sim.granules": granules})
    return [scene_with(base, {"sim.seed": 1000 + i, "spinner.rpm": 500.0 + 40.0 * i}) for i in range(count)]


GUARD_RAISED = []  # the sizes at which the vector env's memory guard had to be raised


def vector_env(num_envs: int, device: Optional[str] = None, granules: Optional[int] = None, workers: int = 1):
    """The SpinnerDesign vector env as shipped (in `workers` processes); where it refuses
    `num_envs` for memory (the code that ran a step as one batch), with that guard raised
    in this process (docstring)."""
    import gymnasium as gym

    import spreadgym  # noqa: F401  (registers the ids)
    from spreadgym.config import scene as scene_config
    from spreadgym.errors import ConfigError

    kwargs: dict = {} if device is None else {"device": device}
    if workers > 1:
        kwargs["workers"] = workers
    if granules is not None:
        kwargs["granules"] = granules
    try:
        return gym.make_vec("spreadgym/SpinnerDesign-v0", num_envs=num_envs, autoreset_mode="same_step", **kwargs)
    except ConfigError as error:
        if error.key != "num_envs":
            raise
        scene_config.MAX_GRANULE_COPIES = 10**9
        GUARD_RAISED.append(num_envs)
        say(f"the vector env refused {num_envs} sub-envs ({error.message[:80]}...): guard raised for this benchmark")
        return gym.make_vec("spreadgym/SpinnerDesign-v0", num_envs=num_envs, autoreset_mode="same_step", **kwargs)


@contextmanager
def stage_timers():
    """Timers around the calls `spreadgym.spread.batch.run_batch` makes, restored after:
    its module's `plan_scene`, `finish_scene` and, where the tree has it, `finish_plain`,
    and `SpinnerModel.run_batch` (the spinner stage). So the stages timed are those of the
    run_batch in this tree, whichever version it is (the finish is being reworked); the
    wrappers cost a clock read per call. Yields the dict the timers add their seconds to."""
    import threading

    from spreadgym.physics.selection import SpinnerModel
    from spreadgym.spread import batch as batch_module

    seconds = {"plan": 0.0, "spinner": 0.0, "spinner_end": 0.0, "finish_scene": 0.0, "finish_plain": 0.0}
    lock = threading.Lock()

    def timer(function, key: str):
        def timed_call(*args, **kwargs):
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                end = time.perf_counter()
                with lock:
                    seconds[key] += end - start
                    if key == "spinner":
                        seconds["spinner_end"] = end
        return timed_call

    names = {"plan_scene": "plan", "finish_scene": "finish_scene", "finish_plain": "finish_plain"}
    saved = {name: getattr(batch_module, name) for name in names if hasattr(batch_module, name)}
    spinner = SpinnerModel.run_batch
    try:
        for name, function in saved.items():
            setattr(batch_module, name, timer(function, names[name]))
        SpinnerModel.run_batch = timer(spinner, "spinner")
        yield seconds
    finally:
        for name, function in saved.items():
            setattr(batch_module, name, function)
        SpinnerModel.run_batch = spinner


def staged_batch(scenes, library, ci: bool = False) -> tuple[list, dict]:
    """`run_batch(scenes)` with its stages timed (`stage_timers`): wall, plan (the plan_scene
    calls), spinner (the model's batch runs), finish (from the spinner stage's end to the
    return) and the finish calls' own summed time; returns the results and those seconds."""
    from spreadgym.spread import batch as batch_module

    with stage_timers() as seconds:
        start = time.perf_counter()
        results = batch_module.run_batch(scenes, library=library, ci=ci)
        end = time.perf_counter()
    return results, {"wall": end - start, "plan": seconds["plan"], "spinner": seconds["spinner"],
                     "finish": end - seconds["spinner_end"],
                     "finish_calls": seconds["finish_scene"] + seconds["finish_plain"],
                     "finish_plain_calls": seconds["finish_plain"],
                     "models": sorted({r.metrics.model for r in results})}


# ----------------------------------------------------------------------------- the CPU process

def versions(out: Path) -> dict:
    import importlib.metadata as metadata

    import numba

    found = {"python": platform.python_version(), "executable": sys.executable, "machine": platform.machine(),
             "cores_os": os.cpu_count(), "cores_affinity": len(os.sched_getaffinity(0)),
             "numba_num_threads": numba.config.NUMBA_NUM_THREADS,
             "mps": os.environ.get("DEVICE_CHECK_MPS") == "1"}  # device_check.sh's MPS=1, started
    for name in ("numpy", "numba", "llvmlite", "numba-cuda", "scipy", "gymnasium", "pydantic", "pymunk", "cffi",
                 "cuda-bindings", "cuda-pathfinder"):
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    try:
        model = next(line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name"))
    except (OSError, StopIteration):
        model = platform.processor()
    found["cpu"] = model
    try:
        found["gpus"] = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True, timeout=20).stdout.strip()
    except (OSError, subprocess.SubprocessError) as error:
        found["gpus"] = f"nvidia-smi: {error}"
    found["cuda_home"] = os.environ.get("CUDA_HOME")
    found["sources_sha256"] = sources_digests()
    write_json(out / "env.json", found)
    say("versions: " + ", ".join(f"{k} {v}" for k, v in found.items() if k not in ("executable",)))
    return found


def sources_digests() -> dict:
    """The first 12 hex digits of the SHA-256 of the modules whose version the figures depend
    on most (this tree travels uncommitted: compare them with a checkout); None: not in this tree."""
    import hashlib
    import importlib.util

    names = ["spread.batch", "spread.pipeline", "spread.plain_finish", "spread.finish_kernel",
             "physics.compiled.granule_run", "physics.compiled.cuda_spinner", "physics.compiled.model",
             "envs.vector", "envs.common.task", "threads"]
    found = {}
    for name in names:
        try:
            spec = importlib.util.find_spec(f"spreadgym.{name}")
        except ImportError:
            spec = None
        origin = spec.origin if spec is not None else None
        found[name] = hashlib.sha256(Path(origin).read_bytes()).hexdigest()[:12] if origin else None
    return found


def thread_counts(quick: bool, asked: Optional[list[int]] = None) -> list[int]:
    cores = len(os.sched_getaffinity(0))
    counts = [n for n in (asked or FULL_THREADS) if n <= cores]
    return counts[:2] if quick else counts


def count_list(text: str) -> list[int]:
    """`--threads`, contention's `--procs`: whole numbers >= 1, comma-separated."""
    try:
        counts = [int(part) for part in text.split(",")]
    except ValueError:
        counts = []
    if not counts or min(counts) < 1:
        raise argparse.ArgumentTypeError(f"expected counts >= 1 separated by commas, e.g. 1,16; got {text!r}")
    return counts


def cpu_main(args) -> None:
    """The CPU sections, with the GPU process started first; the summary of both at the end."""
    from spreadgym import threads
    from spreadgym.config.materials import load_library
    from spreadgym.spread.batch import run_batch

    out, work = Path(args.out), Path(args.work)
    child = start_gpu_process(args)  # after the imports above, which checked the kernel caches (kernel_cache)
    venv = None
    try:
        env: dict = {}
        with section("versions", 30):
            env = versions(out)
        scaling, stages = Table(out / "cpu_scaling.csv"), Table(out / "cpu_stages.csv")
        counts = [] if args.gpu_only else thread_counts(args.quick, args.threads)
        library = load_library()
        with section("CPU warm-up (numba's first compile, or its cache)", 240):
            threads.set_threads(counts[-1] if counts else None)
            started = time.perf_counter()
            run_batch(mixed_scenes(3, granules=64), library=library, ci=False)
            if counts:
                venv = vector_env(args.batch)
                venv.reset(seed=0)
            env["cpu_warm_s"] = time.perf_counter() - started
            say(f"warm in {env['cpu_warm_s']:.1f} s")
            import numba

            env["numba_threading_layer"] = numba.threading_layer()
            env["vector_env_memory_guard_raised_at"] = list(GUARD_RAISED)
            write_json(out / "env.json", env)

        if counts:
            cpu_series(args, counts, library, venv, work, scaling, stages)
        else:
            say("--gpu-only: no CPU scaling series")
    except Exception as error:  # noqa: BLE001 (outside every section: still wait for the GPU and summarise)
        say(f"!! CPU process: {type(error).__name__}: {error}")
    finally:
        threads.set_threads(None)
        if venv is not None:
            venv.close()
        (work / "cpu_done").write_text(str(time.time()))
        say("CPU sections done; the GPU process may time now")
        if child is not None:
            try:
                child.wait(timeout=max(5.0, CLOCK.left() + 10.0))
            except subprocess.TimeoutExpired:
                say("the GPU process overran the deadline: stopped")
                child.kill()
                child.wait()
        summary(out)


def contention_main(args) -> None:
    """`--contention`: the versions, the kernels warmed, then `contention.measure` at the
    thread counts as process counts (nothing else runs beside it: no GPU process)."""
    from spreadgym.agents import contention
    from spreadgym.config.materials import load_library
    from spreadgym.spread.batch import run_batch

    out = Path(args.out)
    with section("versions", 30):
        versions(out)
    with section("CPU warm-up (numba's first compile, or its cache)", 240):
        run_batch(paper_designs(2, granules=64), library=load_library(), ci=False)
    counts = thread_counts(args.quick, args.threads)
    with section(f"contention probe at {counts} processes", CLOCK.left() - 10.0):
        contention.measure(out, counts, phase_s=2.0 if args.quick else 5.0, say=say)


def cpu_series(args, counts: list[int], library, venv, work: Path, scaling: Table, stages: Table) -> None:
    """The CPU scaling series at `counts` threads (`scaling_rows`, `stage_row`), the
    all-cores count after the CUDA compile has ended."""
    from spreadgym import threads

    scenes, papers = mixed_scenes(args.batch), paper_designs(args.batch)
    reference: dict = {}
    with section(f"CPU scaling at {counts} threads: run_batch of {args.batch} mixed scenes and the vector env "
                 f"({args.batch} sub-envs), then run_batch's stages on {args.batch} paper designs",
                 args.cpu_cap_s) as until:
        until = min(until, CLOCK.t0 + CLOCK.deadline_s - args.gpu_reserve_s)
        for n in counts:
            last = n == counts[-1]
            if last and n > 1:  # measured even when late: the all-cores figure matters most
                wait_for(work / "compiled", min(until - 25.0, time.time() + args.compile_wait_s),
                         f"the CUDA compile to end (the {n}-thread series want the machine to themselves)")
            elif time.time() > until:
                say(f"out of time before {n} threads")
                continue
            threads.set_threads(n)
            guarded(f"scaling at {n} threads", scaling_rows, n, args, scenes, library, venv, reference, scaling,
                    until, work)
            guarded(f"stages at {n} threads", stage_row, n, args, papers, library, reference, stages, until, work)


def scaling_rows(n: int, args, scenes, library, venv, reference: dict, table: Table, until: float,
                 work: Path) -> None:
    """Designs/s of run_batch (mixed scenes), of the vector env and, above one thread, of
    the vector env in `n` worker processes of one thread each (`workers`, envs/shards.py)
    at `n` threads, their blocks interleaved: a warm-up block, then `args.repeats` timed
    ones; bits against 1 thread. Every block resets each env with its own seed and steps
    it with its own actions, alike for both envs, so results compare across thread counts."""
    from spreadgym.spread.batch import run_batch

    envs = {"vector env": venv}
    spread = None
    if venv is not None and n > 1:
        with section(f"{n} worker processes start", 120):
            spread = vector_env(args.batch, workers=n)
        envs[f"vector env, {n} workers"] = spread
    rates: dict = {what: [] for what in ("run_batch mixed", *envs)}
    rewards: dict = {what: [] for what in envs}
    last, block_s = None, 0.0
    try:
        for block in range(args.repeats + 1):
            if block > 1 and time.time() + block_s > until:
                break
            began = time.perf_counter()
            start = time.perf_counter()
            last = run_batch(scenes, library=library, ci=False)
            if block:
                rates["run_batch mixed"].append(args.batch / (time.perf_counter() - start))
            for what, env in envs.items():
                if env is None:
                    continue
                env.action_space.seed(block)
                actions = env.action_space.sample()
                env.reset(seed=1000 * block)
                start = time.perf_counter()
                obs, reward, *_ = env.step(actions)
                if block:
                    rates[what].append(args.batch / (time.perf_counter() - start))
                rewards[what].append((obs.copy(), reward.copy()))
            block_s = time.perf_counter() - began
    finally:
        if spread is not None:
            spread.close()
    masses = [r.replicate_masses_kg for r in last]
    reference.setdefault("masses", masses)
    reference.setdefault("rewards", rewards.get("vector env"))

    def equal(found: list) -> bool:  # observations and rewards, block by block, as at the first thread count
        return all(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
                   for a, b in zip(found, reference["rewards"] or []))

    same = {"run_batch mixed": all(np.array_equal(a, b) for a, b in zip(masses, reference["masses"])),
            **{what: equal(found) for what, found in rewards.items()}}
    for what, found in rates.items():
        if not found:
            continue
        median, low, high = spread_of(found)
        table.add({"what": what, "batch": args.batch, "threads": n, "designs_per_s": median, "low": low,
                   "high": high, "same_bits": same[what], "blocks": len(found),
                   "gpu_compile_running": not (work / "compiled").exists()})
        say(f"{what:16s} {n:2d} threads: {median:7.1f} designs/s ({low:.1f}-{high:.1f}, {len(found)} blocks) "
            f"same bits as 1 thread: {same[what]}")


def stage_row(n: int, args, papers, library, reference: dict, table: Table, until: float, work: Path) -> None:
    """run_batch's stage times on the paper designs at `n` threads, median of up to `args.repeats` blocks."""
    found, results = [], None
    for _ in range(args.repeats):
        if found and time.time() + found[-1]["wall"] > until:
            break
        results, seconds = staged_batch(papers, library)
        found.append(seconds)
    masses = [r.replicate_masses_kg for r in results]
    reference.setdefault("paper_masses", masses)
    row = {"threads": n, "designs": args.batch, "blocks": len(found), "models": "+".join(found[0]["models"])}
    for key in ("wall", "plan", "spinner", "finish", "finish_calls", "finish_plain_calls"):
        row[f"{key}_ms_per_design"] = statistics.median(s[key] for s in found) * 1e3 / args.batch
    row["same_bits"] = all(np.array_equal(a, b) for a, b in zip(masses, reference["paper_masses"]))
    row["gpu_compile_running"] = not (work / "compiled").exists()
    table.add(row)
    say(f"stages {n:2d} threads (ms/design): wall {row['wall_ms_per_design']:.2f} = plan "
        f"{row['plan_ms_per_design']:.2f} + spinner {row['spinner_ms_per_design']:.2f} + finish "
        f"{row['finish_ms_per_design']:.2f} (finish calls' own time {row['finish_calls_ms_per_design']:.2f})")


def start_gpu_process(args) -> Optional[subprocess.Popen]:
    """The GPU process (this module, --role gpu), started now so that its compile overlaps
    the CPU series; it shares this process's clock, output folder and flag folder."""
    command = [sys.executable, "-P", "-m", "spreadgym.agents.device_check", "--role", "gpu", "--t0", str(CLOCK.t0),
               "--deadline-s", str(CLOCK.deadline_s), "--out", args.out, "--work", args.work]
    command += ["--quick"] if args.quick else []
    command += ["--gpu-sim"] if args.gpu_sim else []
    environment = dict(os.environ, PYTHONUNBUFFERED="1")
    if args.gpu_sim:
        environment["NUMBA_ENABLE_CUDASIM"] = "1"
    try:
        child = subprocess.Popen(command, env=environment)
    except OSError as error:
        say(f"!! could not start the GPU process: {error}")
        return None
    say(f"GPU process started (pid {child.pid})")
    return child


# ----------------------------------------------------------------------------- the GPU process

def gpu_main(args) -> None:
    global TAG
    TAG = "[gpu]"
    from spreadgym import device, threads
    from spreadgym.config.materials import load_library

    out, work = Path(args.out), Path(args.work)
    report: dict = {"sim": bool(args.gpu_sim)}
    toy = args.gpu_sim
    granules = 16 if toy else None  # None: the scenes' own 2048
    try:
        if not device.cuda_available():
            say("no CUDA GPU here (numba.cuda sees none): GPU sections skipped")
            report["skipped"] = "no CUDA GPU found by numba.cuda"
            return
        with section("CUDA compile of the spinner kernel (a small paper batch)", 420):
            from numba import cuda

            try:
                gpu = cuda.get_current_device()
                report["gpu"] = {"name": str(gpu.name.decode() if isinstance(gpu.name, bytes) else gpu.name),
                                 "compute_capability": list(getattr(gpu, "compute_capability", ()))}
            except AttributeError:  # numba's CUDA simulator has no device object
                report["gpu"] = {"name": "numba's CUDA simulator"}
            say(f"device: {report['gpu']}")
            from spreadgym.physics.compiled.model import simulate_compiled_batch
            from spreadgym.spread.pipeline import plan_scene

            library = load_library()
            runs = plan_scene(paper_designs(1, granules=64)[0], "auto", library).spinner_runs()
            started = time.perf_counter()
            try:
                with device.using("cuda"):
                    simulate_compiled_batch(runs)
            except Exception as error:  # the one failure worth its whole traceback (a toolkit or driver problem)
                report["compile_error"] = f"{type(error).__name__}: {error}"[:4000]
                print(traceback.format_exc()[-4000:], flush=True)
                raise
            report["compile_and_first_launch_s"] = time.perf_counter() - started
            started = time.perf_counter()
            with device.using("cuda"):
                simulate_compiled_batch(runs)
            report["second_launch_s"] = time.perf_counter() - started
            say(f"compiled and launched in {report['compile_and_first_launch_s']:.1f} s; "
                f"again in {report['second_launch_s'] * 1e3:.1f} ms")
    finally:
        write_json(out / "gpu.json", report)
        (work / "compiled").write_text(json.dumps(report, default=str))
    if "compile_and_first_launch_s" not in report:
        say("no compiled kernel: GPU sections skipped")
        return
    if not wait_for(work / "cpu_done", time.time() + max(0.0, CLOCK.left() - 30.0), "the CPU sections to end"):
        return
    library = load_library()
    cores = min(16, len(os.sched_getaffinity(0)))
    threads.set_threads(cores)
    try:
        with section("GPU against CPU on one batch", 60):
            report["match"] = compare_devices(library, granules, toy)
            write_json(out / "gpu.json", report)
        # in the order of what is least known: the GPU target's own figure (the vector env, with workers), the
        # queue's schedule, then the spinner stage
        with section("the vector env and run_batch, cuda against cpu", args.batch_cap_s) as until:
            whole_batches(Table(out / "gpu_batch.csv"), library, until, granules, toy, cores)
        spinner = Table(out / "gpu_spinner.csv")
        with section("GPU schedules of the spinner kernel", 60) as until:
            schedules(spinner, library, until, granules, toy, cores)
        with section("spinner stage alone: GPU, CPU 1 and 16 threads", args.spinner_cap_s) as until:
            spinner_stage(spinner, library, until, granules, toy, cores)
    finally:
        threads.set_threads(None)
        write_json(out / "gpu.json", report)


def compare_devices(library, granules: Optional[int], toy: bool) -> dict:
    """CPU and GPU results of one batch: paper designs of varied rpm and seed, then twin-field and field scenes."""
    from spreadgym import device
    from spreadgym.spread.batch import run_batch

    count, extra = (4, 1) if toy else (64, 4)
    scenes = paper_designs(count, granules) + others("twin-field", extra, granules) + others("field", extra, granules)
    found = {}
    for name in ("cpu", "cuda"):
        with device.using(name):
            started = time.perf_counter()
            found[name] = run_batch(scenes, library=library, ci=False)
            say(f"{len(scenes)} scenes on {name}: {time.perf_counter() - started:.2f} s")
    rows = []
    for scene, cpu, gpu in zip(scenes, found["cpu"], found["cuda"]):
        a, b = cpu.departure, gpu.departure
        speed = np.abs(a.speed_m_s - b.speed_m_s)
        both = a.departed & b.departed
        scale = float(np.abs(cpu.replicate_masses_kg).max()) or 1.0
        cv_a, cv_b = cpu.metrics.cv_percent_at_target, gpu.metrics.cv_percent_at_target
        rows.append({
            "scene": scene.name, "granules": int(a.outcome.shape[0]),
            "outcome_counts_equal": cpu.metrics.outcomes == gpu.metrics.outcomes,
            "granule_outcomes_differing": int((a.outcome != b.outcome).sum()),
            "speed_diff_over_1e-9": int((speed > 1e-9).sum()),
            "speed_diff_over_1e-9_departed_both": int((speed[both] > 1e-9).sum()),
            "max_speed_diff_departed_both": float(speed[both].max(initial=0.0)),
            "masses_bit_equal": bool(np.array_equal(cpu.replicate_masses_kg, gpu.replicate_masses_kg)),
            "max_mass_diff_relative": float(np.abs(cpu.replicate_masses_kg - gpu.replicate_masses_kg).max()) / scale,
            "cv_diff_pp": None if cv_a is None or cv_b is None else float(cv_b - cv_a),
        })
    cv = [abs(r["cv_diff_pp"]) for r in rows if r["cv_diff_pp"] is not None]
    total = sum(r["granules"] for r in rows)
    summary = {
        "scenes": len(rows), "granules": total,
        "designs_with_equal_outcome_counts": sum(r["outcome_counts_equal"] for r in rows),
        "granule_outcomes_differing": sum(r["granule_outcomes_differing"] for r in rows),
        "granules_speed_diff_over_1e-9": sum(r["speed_diff_over_1e-9"] for r in rows),
        "granules_speed_diff_over_1e-9_departed_both": sum(r["speed_diff_over_1e-9_departed_both"] for r in rows),
        "max_speed_diff_departed_both_m_s": max(r["max_speed_diff_departed_both"] for r in rows),
        "designs_with_bit_equal_masses": sum(r["masses_bit_equal"] for r in rows),
        "max_mass_diff_relative": max(r["max_mass_diff_relative"] for r in rows),
        "max_abs_cv_diff_pp": max(cv) if cv else None,
        "median_abs_cv_diff_pp": statistics.median(cv) if cv else None,
    }
    say("match: " + ", ".join(f"{k} {v}" for k, v in summary.items()))
    return {"summary": summary, "per_design": rows}


def spinner_runs_of(count: int, library, granules: Optional[int], unique: int = 512):
    """The spinner runs of `count` paper designs: `unique` planned ones (building and
    validating a scene costs ~3 ms, planning it ~0.4), repeated in turn: the kernel's work
    per granule does not depend on whether a design came before."""
    from spreadgym.spread.pipeline import plan_scene

    plans = [plan_scene(scene, "auto", library, 0) for scene in paper_designs(min(count, unique), granules)]
    models = {plan.chosen for plan in plans}
    if models != {"compiled"}:
        raise RuntimeError(f"expected the compiled model for every paper design, got {sorted(models)}")
    runs = [run for plan in plans for run in plan.spinner_runs()]
    return [runs[i % len(runs)] for i in range(count)]


def spinner_stage(table: Table, library, until: float, granules: Optional[int], toy: bool, cores: int) -> None:
    """simulate_compiled_batch on the GPU and on the CPU (1 and all threads) at growing batch sizes."""
    from numba import cuda

    from spreadgym import device, threads
    from spreadgym.physics.compiled import model

    sizes = (2, 4) if toy else (64, 256, 1024, 4096)
    started = time.perf_counter()
    runs = spinner_runs_of(max(sizes), library, granules)
    say(f"planned {len(runs)} paper designs in {time.perf_counter() - started:.1f} s")
    rate: dict = {}  # (device, threads) -> seconds per design at the last size measured

    def measure(name: str, n: int, size: int) -> None:
        key, part = (name, n), runs[:size]
        guess = rate.get(key, 0.0) * size
        if guess > min(20.0, until - time.time() - 5.0):
            say(f"skip {name} {n} threads at {size} designs (about {guess:.0f} s a call)")
            return
        n_granules = sum(run[1].radius_m.shape[0] for run in part)
        threads.set_threads(n)
        sync = cuda.synchronize if name == "cuda" else (lambda: None)
        with device.using(name):
            times, _ = timed(lambda: model.simulate_compiled_batch(part), 3, min(until, time.time() + 12.0),
                             warm=key not in rate or guess < 2.0, sync=sync)
            median, low, high = spread_of(times)
            split = split_call(part) if (name == "cuda" or n > 1) and median < 3.0 else {}
        rate[key] = median / size
        row = {"device": name, "threads": n, "threads_per_block": threads_per_block() if name == "cuda" else None,
               "designs": size, "granules": n_granules, "repeats": len(times), "median_s": median,
               "low_s": low, "high_s": high, "granule_runs_per_s": n_granules / median,
               "designs_per_s": size / median, **split}
        table.add(row)
        say(f"spinner {name:4s} {n:2d} thr {size:5d} designs: {median * 1e3:9.1f} ms "
            f"({row['designs_per_s']:9.1f} designs/s, {row['granule_runs_per_s'] / 1e6:7.2f} M granule-runs/s)"
            + (f" [inputs {split['inputs_s'] * 1e3:.0f} ms, kernel+copies {split['kernels_s'] * 1e3:.0f} ms, "
               f"frames {split['frames_s'] * 1e3:.0f} ms]" if split else ""))

    for name, n in (("cuda", cores), ("cpu", cores), ("cpu", 1)):  # the GPU's row first: the figure sought
        for size in sizes:
            guarded(f"spinner {name} {n} threads {size} designs", measure, name, n, size)
    threads.set_threads(cores)


def split_call(runs) -> dict:
    """One simulate_compiled_batch done in its three steps with timers (packing the inputs on
    one thread, the kernel with its copies, the turn to the machine frame on the threads)."""
    from spreadgym.physics.compiled import model
    from spreadgym.threads import thread_map

    t0 = time.perf_counter()
    batch = [model.kernel_inputs(*run) for run in runs]
    t1 = time.perf_counter()
    results = model.run_kernels(batch)
    t2 = time.perf_counter()
    thread_map(lambda i: model.departure_from(batch[i], runs[i][0].spinner.omega_rad_s, *results[i]), len(runs))
    t3 = time.perf_counter()
    return {"inputs_s": t1 - t0, "kernels_s": t2 - t1, "frames_s": t3 - t2}


def threads_per_block() -> int:
    from spreadgym.physics.compiled import cuda_spinner

    return cuda_spinner.THREADS_PER_BLOCK


def schedules(table: Table, library, until: float, granules: Optional[int], toy: bool, cores: int) -> None:
    """The spinner kernel alone (inputs packed beforehand; the queue's order, the copies and
    the launch timed) under three schedules, at 1024 and 4096 paper designs: the shipped
    queue handing out granules longest first, the queue in launch order, and one granule
    per thread in launch order (the schedule before the queue). The outputs of the three
    must be equal to the bit (each granule's arithmetic is the same whichever thread runs it)."""
    from numba import cuda

    from spreadgym.physics.compiled import cuda_spinner, granule_run, model

    sizes = (4,) if toy else (1024, 4096)
    runs = spinner_runs_of(max(sizes), library, granules)
    for size in sizes:
        if time.time() > until - 5.0:
            say(f"out of time before {size} designs")
            break
        arrays, counts = model.kernel_arrays([model.kernel_inputs(*run) for run in runs[:size]])
        n = int(counts.sum())
        started = time.perf_counter()
        model.longest_first(arrays[0], arrays[2], arrays[5])
        order_s = time.perf_counter() - started
        launch_order = np.arange(n)
        found = {}
        for name, kwargs in (("queue, longest first (shipped)", {}), ("queue, launch order", {"order": launch_order}),
                             ("one granule per thread", {"order": launch_order, "queue": False})):
            out, outcome = np.zeros((n, granule_run.OUT_SIZE)), np.zeros(n, dtype=np.int8)
            launch = partial(cuda_spinner.run_all, *arrays, out, outcome, **kwargs)
            if time.time() > until - 2.0:
                say(f"out of time before {name} at {size} designs")
                continue
            times, _ = timed(launch, 3, until, sync=cuda.synchronize)
            found[name] = (out.copy(), outcome.copy())
            median, low, high = spread_of(times)
            same = all(np.array_equal(out, o) and np.array_equal(outcome, c) for o, c in found.values())
            table.add({"device": "cuda", "threads": cores, "threads_per_block": cuda_spinner.THREADS_PER_BLOCK,
                       "designs": size, "granules": n, "repeats": len(times), "median_s": median, "low_s": low,
                       "high_s": high, "granule_runs_per_s": n / median, "designs_per_s": size / median,
                       "note": f"kernel alone, {name}; queue order {order_s * 1e3:.1f} ms; "
                               f"outputs equal to the first schedule's: {same}"})
            say(f"schedule {name:32s} {size:5d} designs: {median * 1e3:8.1f} ms ({size / median:8.1f} designs/s), "
                f"equal bits: {same}")


def whole_batches(table: Table, library, until: float, granules: Optional[int], toy: bool, cores: int) -> None:
    """run_batch of paper designs and the vector env's steps, device cuda and cpu, all
    threads; the vector env on cuda also in `cores` worker processes sharing the GPU (one
    thread each), its rewards compared to the one-process GPU run's to the bit."""
    from numba import cuda

    from spreadgym import device
    from spreadgym.spread.batch import run_batch

    sizes = (4, 2) if toy else (1024, 256)  # the larger first: where a GPU should pay
    scenes = paper_designs(max(sizes), granules, seed0=5000)
    rewards: dict = {}

    def batch_rate(name: str, size: int, workers: int) -> None:
        sync = cuda.synchronize if name == "cuda" else (lambda: None)
        with device.using(name):
            times, _ = timed(lambda: run_batch(scenes[:size], library=library, ci=False), 3,
                             min(until, time.time() + 15.0), sync=sync)
        median, low, high = spread_of(times)
        table.add({"what": "run_batch paper", "device": name, "threads": cores, "workers": workers, "batch": size,
                   "designs_per_s": size / median, "low": size / high, "high": size / low, "repeats": len(times)})
        say(f"run_batch  {name:4s} {size:5d}: {size / median:8.1f} designs/s ({len(times)} blocks)")

    def env_rate(name: str, size: int, workers: int) -> None:
        started = time.perf_counter()
        venv = vector_env(size, device=name, granules=granules, workers=workers)
        steps: list = []
        try:
            venv.reset(seed=0)
            venv.action_space.seed(0)
            built_s = time.perf_counter() - started
            times, _ = timed(lambda: steps.append(venv.step(venv.action_space.sample())[1]), 3,
                             min(until, time.time() + 15.0))
        finally:
            venv.close()
        rewards[name, size, workers] = np.concatenate(steps)
        median, low, high = spread_of(times)
        row = {"what": "vector env steps", "device": name, "threads": cores, "workers": workers, "batch": size,
               "designs_per_s": size / median, "low": size / high, "high": size / low, "repeats": len(times),
               "built_and_reset_s": built_s}
        other, mine = rewards.get(("cuda", size, 1)), rewards[name, size, workers]
        if (name, workers) != ("cuda", 1) and other is not None:  # every run steps from the same seeds and actions
            both = min(other.size, mine.size)  # the steps both timed
            row["max_abs_reward_diff_vs_cuda"] = float(np.abs(mine[:both] - other[:both]).max())
        table.add(row)
        say(f"vector env {name:4s} {size:5d} {workers:2d} workers: {size / median:8.1f} steps/s ({len(times)} blocks)"
            + (f", max |reward - cuda's| {row['max_abs_reward_diff_vs_cuda']:.3g}"
               if "max_abs_reward_diff_vs_cuda" in row else ""))

    spread = 2 if toy else cores  # worker processes sharing the GPU
    for what, measure, reserve, runs in (
            ("vector env", env_rate, 15.0, (("cuda", 1), ("cuda", spread), ("cpu", 1))),  # first: the new figure
            ("run_batch", batch_rate, 10.0, (("cuda", 1), ("cpu", 1)))):
        for size in sizes:
            for name, workers in runs:
                if time.time() > until - reserve:
                    say(f"out of time before {what} {name} {size} ({workers} workers)")
                    continue
                guarded(f"{what} {name} {size} ({workers} workers)", measure, name, size, workers)


# ----------------------------------------------------------------------------- summary

def summary(out: Path) -> None:
    """The figures of every file written, as one short table."""
    def rows_of(name):
        path = out / name
        if not path.exists():
            return []
        with open(path) as f:
            return list(csv.DictReader(f))

    def num(value, digits=1):
        try:
            return f"{float(value):.{digits}f}"
        except (TypeError, ValueError):
            return "-"

    lines = ["", "SUMMARY (designs/s unless said)"]
    scaling = rows_of("cpu_scaling.csv")
    if scaling:
        counts = sorted({int(r["threads"]) for r in scaling})
        lines.append(f"{'CPU scaling':30s}" + "".join(f"{n:>9d}t" for n in counts) + "  same bits")
        for what in dict.fromkeys(r["what"] for r in scaling):
            by = {int(r["threads"]): r for r in scaling if r["what"] == what}
            lines.append(f"  {what + ' (' + scaling[0]['batch'] + ')':28s}"
                         + "".join(f"{num(by[n]['designs_per_s']) if n in by else '-':>10s}" for n in counts)
                         + "  " + str(all(r["same_bits"] == "True" for r in by.values())))
    stages = rows_of("cpu_stages.csv")
    if stages:
        lines.append("CPU stages, ms/design: threads  wall  plan  spinner  finish  (finish calls)")
        for r in stages:
            lines.append(f"  {r['threads']:>22s} {num(r['wall_ms_per_design'], 2):>6s}"
                         f" {num(r['plan_ms_per_design'], 2):>5s}"
                         f" {num(r['spinner_ms_per_design'], 2):>8s} {num(r['finish_ms_per_design'], 2):>7s}"
                         f"  ({num(r['finish_calls_ms_per_design'], 2)})")
    gpu_path = out / "gpu.json"
    if gpu_path.exists():
        gpu = json.loads(gpu_path.read_text())
        if "skipped" in gpu:
            lines.append(f"GPU: skipped ({gpu['skipped']})")
        elif "compile_and_first_launch_s" not in gpu:
            lines.append(f"GPU: no compiled kernel ({gpu.get('compile_error', 'see the log')[:300]})")
        else:
            lines.append(f"GPU: {gpu.get('gpu')}, compile + first launch {num(gpu.get('compile_and_first_launch_s'))} s"
                         + (" (CUDA simulator)" if gpu.get("sim") else ""))
            match = gpu.get("match", {}).get("summary")
            if match:
                lines.append("  GPU vs CPU: " + ", ".join(f"{k}={v}" for k, v in match.items()))
    spinner = rows_of("gpu_spinner.csv")
    if spinner:
        lines.append("Spinner stage (simulate_compiled_batch; kernel alone where a schedule is named), "
                     "designs/s [M granule-runs/s]:")
        for r in spinner:
            note = r.get("note") or ""
            schedule = note.split(";")[0].removeprefix("kernel alone, ") if note.startswith("kernel alone") else ""
            lines.append(f"  {r['device']:4s} {r['threads']:>2s} thr tpb {r['threads_per_block'] or '-':>3s} "
                         f"{r['designs']:>5s} designs: {num(r['designs_per_s']):>9s} "
                         f"[{num(float(r['granule_runs_per_s']) / 1e6, 2)}] x{r['repeats']}"
                         + (f"  {schedule} (same bits: {note.rsplit(': ', 1)[-1]})" if schedule else ""))
    batch = rows_of("gpu_batch.csv")
    if batch:
        lines.append(f"Whole batch of paper designs, {batch[0]['threads']} threads finishing (vector env: steps/s):")
        for r in batch:
            lines.append(f"  {r['what']:18s} {r['device']:4s} {r['batch']:>5s} {r.get('workers') or '1':>2s} workers:"
                         f" {num(r['designs_per_s']):>8s} x{r['repeats']}"
                         + (f"  (max |reward - cuda's| {r['max_abs_reward_diff_vs_cuda']})"
                            if r.get("max_abs_reward_diff_vs_cuda") else ""))
    lines.append(f"total {CLOCK.elapsed():.0f} s")
    print("\n".join(lines), flush=True)


# ----------------------------------------------------------------------------- entry

def main(argv: Optional[list[str]] = None) -> None:
    global CLOCK
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=os.environ.get("OUT") or "out/device-check", help="folder for the figures")
    parser.add_argument("--work", default=None, help="folder for the two processes' flag files")
    parser.add_argument("--quick", action="store_true", help="small sizes, two thread counts: a dry run")
    parser.add_argument("--gpu-sim", action="store_true", help="the GPU section on numba's CUDA simulator, toy sizes")
    parser.add_argument("--gpu-only", action="store_true",
                        help="skip the CPU scaling series (a second call on a machine already measured)")
    parser.add_argument("--contention", action="store_true",
                        help="only the contention probe (agents/contention.py) at the --threads counts: why "
                             "independent one-thread processes keep less than one core's rate each")
    parser.add_argument("--batch", type=int, default=None, help="designs per CPU block (default 256; quick 24)")
    parser.add_argument("--repeats", type=int, default=3, help="timed blocks after the warm-up")
    parser.add_argument("--threads", type=count_list, default=None,
                        help="the CPU series' thread counts, e.g. 1,16 (default 1,2,4,8,16)")
    parser.add_argument("--deadline-s", type=float, default=420.0, help="the whole run's time, both processes")
    parser.add_argument("--compile-wait-s", type=float, default=120.0,
                        help="longest wait for the CUDA compile before the 16-thread CPU series")
    parser.add_argument("--cpu-cap-s", type=float, default=250.0, help="the CPU sections' time after the warm-up")
    parser.add_argument("--gpu-reserve-s", type=float, default=140.0,
                        help="the CPU sections end this long before the deadline at the latest (the GPU's time)")
    parser.add_argument("--spinner-cap-s", type=float, default=75.0)
    parser.add_argument("--batch-cap-s", type=float, default=85.0)
    parser.add_argument("--role", choices=("cpu", "gpu"), default="cpu", help=argparse.SUPPRESS)
    parser.add_argument("--t0", type=float, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    CLOCK = Clock(args.t0 or time.time(), args.deadline_s)
    args.batch = args.batch or (24 if args.quick else 256)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    made = args.work is None  # a flag folder of its own, removed at the end
    if made:
        args.work = tempfile.mkdtemp(prefix="device-check-")
    Path(args.work).mkdir(parents=True, exist_ok=True)
    args.out, args.work = str(Path(args.out).resolve()), str(Path(args.work).resolve())
    if args.role == "gpu":
        gpu_main(args)
        return
    if args.contention:
        contention_main(args)
        return
    try:
        cpu_main(args)
    finally:
        if made:
            shutil.rmtree(args.work, ignore_errors=True)


if __name__ == "__main__":
    main()
