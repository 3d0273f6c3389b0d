"""`spreadgym bench`: speed (and speed against accuracy) measurements, written under docs/.

It sits in the agents layer because it measures every layer, the environments too.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import tempfile
from pathlib import Path

from spreadgym.cli import arguments
from spreadgym.report import format_table

SECTIONS = ("spinner", "methods", "flight", "env", "references", "fidelity", "cv-noise", "targets", "speed-accuracy",
            "stability", "magnus", "chart-scale", "vector-env", "startup", "precision", "honesty", "env-noise",
            "chart-quality", "fit", "batch", "validation", "server", "web",
            "advise", "rl-benchmark", "plates", "gpu-schedule")
"""Every section, in the order `make bench` runs them (`section_runners` gives each its work)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--only", choices=SECTIONS, action="append", help="run only these sections")
    parser.add_argument("--out", type=arguments.output_folder, default=Path("docs/bench"),
                        help="output folder (default docs/bench; the bench's earlier outputs are replaced, "
                             "section by section)")
    arguments.force_flag(parser)
    parser.add_argument("--repeats", type=arguments.COUNT, default=3, help="repeats per timing (median is reported)")


def write_csv(rows: list[dict], path: Path) -> None:
    """The rows as CSV, with every key any row has (in first-seen order; a row without one
    leaves its cell empty: the web section's plate row alone counts aborted requests)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(dict.fromkeys(key for row in rows for key in row)),
                                restval="")
        writer.writeheader()
        writer.writerows(rows)


def section_runners(args: argparse.Namespace, say) -> dict:
    """What each of SECTIONS runs (a callable giving its rows), with `args.out` and `args.repeats`."""
    from spreadgym.agents.advise import bench as advise_bench
    from spreadgym.agents.chart import quality, scale
    from spreadgym.agents.web import bench as web_bench
    from spreadgym.studies import (
        benchmarks,
        estimate_bench,
        fidelity,
        fit_bench,
        gpu_schedule,
        magnus,
        plates,
        references,
        speed_accuracy,
        stability,
        startup,
        validation,
    )

    return {
        "spinner": lambda: benchmarks.spinner_benchmark(repeats=args.repeats),
        "methods": lambda: benchmarks.method_speed_benchmark(repeats=args.repeats),
        "flight": lambda: benchmarks.flight_benchmark(repeats=max(args.repeats, 5)),
        "env": lambda: env_steps_per_second(),
        "references": lambda: reference_rows(references, args.out / "references", say),
        "fidelity": lambda: fidelity_rows(fidelity, args.out, say),
        "cv-noise": lambda: estimate_bench.cv_noise_rows(),
        "targets": lambda: target_rows(estimate_bench, args.out, say),
        "speed-accuracy": lambda: speed_accuracy.speed_accuracy_rows(args.out / "references", progress=say),
        "stability": lambda: stability.stability_rows(
            stability.plot_stability_map(args.out.parent / "stability_map.png")),
        "magnus": lambda: magnus.magnus_rows(args.out.parent / "magnus" / "magnus_effect.png",
                                             repeats=max(args.repeats, 15), progress=say),
        "chart-scale": lambda: scale.chart_scale_rows(repeats=args.repeats, progress=say),
        "vector-env": lambda: vector_env_steps_per_second(repeats=args.repeats),
        "startup": lambda: startup.startup_rows(repeats=args.repeats),
        "precision": lambda: precision_rows(estimate_bench, args.out, say),
        "honesty": lambda: honesty_rows(estimate_bench, args.out, say),
        "env-noise": lambda: env_reward_noise(),
        "chart-quality": lambda: quality.chart_quality_rows(progress=say),
        "fit": lambda: fit_bench.fit_bench_rows(args.out, tests=40, workers=max(1, len(os.sched_getaffinity(0)) // 2),
                                                progress=say),
        "batch": lambda: batch_rows(repeats=max(args.repeats, 5)),
        "validation": lambda: validation.write_validation(args.out, say),
        "server": lambda: server_rows(args.repeats),
        "web": lambda: web_bench.web_rows(repeats=max(args.repeats, 5), progress=say),
        "advise": lambda: advise_bench.advise_bench_rows(args.out / "advise", tests=20, progress=say),
        "rl-benchmark": lambda: rl_benchmark_rows(args.out, say),
        "plates": lambda: plate_rows(plates, args.out, say),
        "gpu-schedule": lambda: gpu_schedule.schedule_rows(),
    }


def run(args: argparse.Namespace) -> int:
    from spreadgym.errors import SpreadgymError
    from spreadgym.out_folder import OutFolder

    if args.repeats < 1:
        raise SpreadgymError(f"--repeats: {args.repeats} must be at least 1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")

    def say(text: str) -> None:
        print(text, file=sys.stderr)

    sections = args.only or list(SECTIONS)
    out = OutFolder(args.out, "bench", force=args.force, keeps_partial=True)
    out.check()
    with out.writing():  # each section's files as it finishes: an interrupted bench keeps the finished ones
        for name in sections:
            run_section(args, name, say)
    return 0


def run_section(args: argparse.Namespace, name: str, say) -> None:
    """One section: its rows computed, written (CSV, and a picture where it has one) and printed."""
    from spreadgym.agents.chart import scale
    from spreadgym.studies import estimate_bench, speed_accuracy

    plots = {"cv-noise": estimate_bench.plot_cv_noise, "speed-accuracy": speed_accuracy.plot_speed_accuracy,
             "chart-scale": scale.plot_chart_scale}
    rows = section_runners(args, say)[name]()
    write_csv(rows, args.out / f"{name}.csv")
    if name in plots:
        plots[name](rows, args.out / f"{name}.png")
    print(f"[{name}]")
    print(format_table([list(r.values()) for r in rows], list(rows[0])))
    print()


def server_rows(repeats: int) -> list[dict]:
    """`spreadgym serve` under load, measured from outside (agents.web.stress), on an empty charts folder."""
    import tempfile

    from spreadgym.agents.web.stress import server_rows as measured

    with tempfile.TemporaryDirectory() as charts:
        return measured(Path(charts), repeats)


def rl_benchmark_rows(out: Path, say) -> list[dict]:
    """The RL benchmark (docs/benchmark.md): trains and scores what runs/benchmark still lacks
    (hours on two cores; resumable), then the baseline table with every rung's steps/s."""
    from spreadgym.agents import benchmark

    return benchmark.benchmark_rows(Path("runs/benchmark"), out, progress=say)


def reference_rows(references, out: Path, say) -> list[dict]:
    """Converged references of the family (resumed from `out`), full and fast model, with tables."""
    rows = []
    for model in ("pymunk", "compiled", "analytic"):
        results = references.compute_references(out, model=model, progress=say)  # also writes <model>.md
        rows += [{"model": model, "scene": r["name"], "cv_percent": r["cv_percent_at_target"],
                  "cv_standard_error_percent": r["cv_standard_error_percent"],
                  "effective_swath_m": r["effective_swath_m"], "granules": r["granules"]} for r in results]
    return rows


def fidelity_rows(fidelity, out: Path, say) -> list[dict]:
    """The compiled model against the converged full model on every reference scene: a
    table (fidelity.md) and six-panel figures (fidelity/<scene>.png)."""
    rows = fidelity.fidelity_rows(out / "references", figures=out / "fidelity", progress=say)
    (out / "fidelity.md").write_text(fidelity.fidelity_markdown(rows), encoding="utf-8")
    return rows


def target_rows(estimate_bench, out: Path, say) -> list[dict]:
    """The estimate's targets on every reference scene, full and fast model; also as markdown."""
    rows = []
    for model in ("pymunk", "compiled", "analytic"):
        rows += estimate_bench.target_rows(out / "references", model=model, progress=say)
    (out / "estimate-targets.md").write_text(estimate_bench.targets_markdown(rows), encoding="utf-8")
    return rows


def honesty_rows(estimate_bench, out: Path, say) -> list[dict]:
    """simulate's stated standard error against its scatter over 128 seeds on every
    reference scene, and one run's; also as markdown."""
    rows = estimate_bench.honesty_rows(seeds=HONESTY_SEEDS, progress=say)
    (out / "honesty.md").write_text(estimate_bench.honesty_markdown(rows), encoding="utf-8")
    return rows


HONESTY_SEEDS = 128  # the observed s.d. then carries about +-12 % (95 %); at 32 seeds it was +-25 %, the target itself


def precision_rows(estimate_bench, out: Path, say) -> list[dict]:
    """simulate's default precision against the converged full model; also as markdown."""
    rows = estimate_bench.precision_rows(out / "references", progress=say)
    (out / "precision.md").write_text(estimate_bench.precision_markdown(rows), encoding="utf-8")
    return rows


def plate_rows(plates, out: Path, say) -> list[dict]:
    """The compiled plate stage against the pymunk one on the reference family's plate
    settings, paired on the same departures; also as markdown (plates.md)."""
    rows = plates.plate_stage_rows(progress=say)
    (out / "plates.md").write_text(plates.plates_markdown(rows), encoding="utf-8")
    return rows


def env_reward_noise(seeds: int = 24) -> list[dict]:
    """SpinnerDesign at its default budget: the s.d. over seeds of the CV (pp) and of the
    reward for one job and one action (compound 10-16-10 on the paper scene's own job,
    the scene's settings), on each shipped single-disc scene. The noise an agent sees."""
    import gymnasium as gym
    import numpy as np

    import spreadgym  # noqa: F401  (registers the ids)

    rows = []
    for scene in ("paper", "field", "paper-deflectors"):
        env = gym.make("spreadgym/SpinnerDesign-v0", scene=scene)
        base = env.unwrapped.task.base_scene
        job = {"fertilizer": base.fertilizer, "target_swath_m": base.pattern.target_swath_m,
               "forward_speed_m_s": 0.0, "wind_m_s": [0.0, 0.0]}
        smap = env.unwrapped.task.settings_map
        action = smap.to_unit(smap.from_scene(base)).astype(np.float32)
        cvs, rewards = [], []
        for seed in range(seeds):
            env.reset(seed=seed, options={"context": job})
            _, reward, _, _, info = env.step(action)
            cvs.append(info["metrics"]["cv_percent_at_target"])
            rewards.append(reward)
        rows.append({"scene": scene, "granules": base.sim.granules, "seeds": seeds,
                     "cv_mean_percent": float(np.mean(cvs)), "cv_sd_pp": float(np.std(cvs, ddof=1)),
                     "reward_mean": float(np.mean(rewards)), "reward_sd": float(np.std(rewards, ddof=1))})
    return rows


def env_steps_per_second(steps: int = 20, repeats: int = 5) -> list[dict]:
    """Env steps per second at the default config of each environment (one process), on
    the paper, field, twin-field and plate scenes: the median of `repeats` blocks of `steps`
    random steps after one warm-up step (which compiles the fast model), with the blocks'
    range."""
    import statistics
    import time

    import gymnasium as gym

    rows = []
    for env_id in ("spreadgym:SpinnerDesign-v0", "spreadgym:SpreaderTuning-v0"):
        for scene in ("paper", "field", "twin-field", "paper-deflectors"):
            env = gym.make(env_id, scene=scene)
            env.reset(seed=0)
            env.action_space.seed(0)
            env.step(env.action_space.sample())
            env.reset()  # the warm-up step may have ended the episode
            rates = []
            for _ in range(repeats):
                start = time.perf_counter()
                for _ in range(steps):
                    _, _, terminated, truncated, info = env.step(env.action_space.sample())
                    if terminated or truncated:
                        env.reset()
                rates.append(steps / (time.perf_counter() - start))
            config = env.unwrapped.config
            rows.append({"env": env_id, "scene": scene, "model": info["metrics"]["model"], "granules": config.granules,
                         "steps_per_s": statistics.median(rates), "steps_per_s_low": min(rates),
                         "steps_per_s_high": max(rates), "ms_per_step": 1e3 / statistics.median(rates)})
            env.close()
    return rows


def vector_env_steps_per_second(batch: int = 64, vector_steps: int = 2, repeats: int = 3) -> list[dict]:
    """Env steps per second of the native SpinnerDesign vector env at `batch` sub-envs
    (same-step autoreset) against the single env on the same number of random steps, at
    the default config on the paper scene, in one process: the median over `repeats`
    blocks of `vector_steps` batched steps (`vector_steps` x `batch` single steps), with
    the blocks' range."""
    import statistics
    import time

    import gymnasium as gym

    def rates_of(step_block) -> list[float]:
        step_block()  # warm-up (compiles or loads the fast model)
        rates = []
        for _ in range(repeats):
            start = time.perf_counter()
            step_block()
            rates.append(vector_steps * batch / (time.perf_counter() - start))
        return rates

    venv = gym.make_vec("spreadgym/SpinnerDesign-v0", num_envs=batch, autoreset_mode="same_step")
    venv.reset(seed=0)
    venv.action_space.seed(0)
    vector = rates_of(lambda: [venv.step(venv.action_space.sample()) for _ in range(vector_steps)])
    venv.close()
    env = gym.make("spreadgym:SpinnerDesign-v0")
    env.reset(seed=0)
    env.action_space.seed(0)

    def single_block():
        for _ in range(vector_steps * batch):
            env.step(env.action_space.sample())
            env.reset()
    single = rates_of(single_block)
    env.close()
    return [{"env": name, "batch": size, "steps_per_s": statistics.median(rates), "steps_per_s_low": min(rates),
             "steps_per_s_high": max(rates), "ratio_to_single": statistics.median(rates) / statistics.median(single)}
            for name, size, rates in (("SpinnerDesignVectorEnv", batch, vector), ("gym.make, one env", 1, single))]


def batch_rows(batch: int = 64, repeats: int = 5) -> list[dict]:
    """Designs per second evaluated one by one and as batches (spreadgym.spread.batch), at
    one thread and at every thread spreadgym may use: SpinnerDesign's single env against
    its native vector env at `batch` sub-envs (default config, paper scene; also in one
    worker process per thread, `workers`), and `run_scene` calls against one `run_batch`
    on paper, field and twin-field scenes of mixed settings. Each figure is the median of
    `repeats` blocks of `batch` designs, with the blocks' range; the series' blocks are
    interleaved so that a shared machine's load falls on all of them alike. Ratios are to
    each group's first row: the one-by-one figure at one thread, and for `train`'s envs
    (`training_env_rows`) SubprocVecEnv at the shipped config's 2 envs."""
    import gymnasium as gym

    from spreadgym import threads
    from spreadgym.studies.benchmarks import batch_series, interleaved_rates

    everything = threads.thread_count()
    venv = gym.make_vec("spreadgym/SpinnerDesign-v0", num_envs=batch, autoreset_mode="same_step")
    venv.reset(seed=0)
    venv.action_space.seed(0)
    env = gym.make("spreadgym:SpinnerDesign-v0")
    env.reset(seed=0)
    env.action_space.seed(0)

    def single_block():
        for _ in range(batch):
            env.step(env.action_space.sample())
            env.reset()

    ways = {("SpinnerDesign, one env", 1): single_block,
            (f"SpinnerDesignVectorEnv ({batch})", batch): lambda: venv.step(venv.action_space.sample())}
    series = {(name, size, n): run for (name, size), run in ways.items() for n in sorted({1, everything})}
    spread = None
    if everything > 1:  # a worker process per thread, each with one (envs/shards.py)
        spread = gym.make_vec("spreadgym/SpinnerDesign-v0", num_envs=batch, autoreset_mode="same_step",
                              workers=everything)
        spread.reset(seed=0)
        spread.action_space.seed(0)
        series[(f"SpinnerDesignVectorEnv ({batch}), {everything} workers", batch, everything)] = (
            lambda: spread.step(spread.action_space.sample()))
    try:
        rows, _ = interleaved_rates(series, batch, repeats)
    finally:
        if spread is not None:
            spread.close()
    venv.close()
    env.close()
    core = batch_series(batch, repeats)
    users = batch_user_rows(batch, repeats) + [training_env_rows(repeats=repeats)]
    for group in [rows, core, *users]:
        base = group[0]["designs_per_s"]  # one by one at one thread; SubprocVecEnv at 2 envs for train's
        for row in group:
            row["ratio_to_group_first_row"] = row["designs_per_s"] / base
    return rows + core + [row for group in users for row in group]


def training_env_rows(designs: int = 64, repeats: int = 5, counts: tuple = (2, 8)) -> list[dict]:
    """`spreadgym train`'s envs (the shipped PPO config: SpinnerDesign-v0, 1000 granules) as
    SB3's SubprocVecEnv (one process per env, threads shared out) and as the batched vector
    env (`vec_env: batched`, one worker per thread), at each of `counts` envs: designs per
    second over blocks of `designs` env steps, median of `repeats` interleaved blocks and
    their range. Every series steps the same seeded actions; the last rewards of the two
    kinds at each count are checked equal. The first row (SubprocVecEnv, `counts[0]` envs,
    the shipped config's n_envs) is the group's base."""
    import numpy as np

    from spreadgym import threads
    from spreadgym.agents.run_config import default_config_path, read_config, validate_config
    from spreadgym.agents.training_env import make_training_env
    from spreadgym.studies.benchmarks import interleaved_rates

    shipped = validate_config("ppo", read_config(default_config_path("ppo")), "shipped")
    everything = threads.thread_count()
    names = {"subproc": "SubprocVecEnv", "batched": "batched vector env"}
    envs, series = [], {}
    try:
        with tempfile.TemporaryDirectory(prefix="spreadgym-bench-") as errors:
            for n in counts:
                for kind in ("subproc", "batched"):
                    env = make_training_env(shipped.replace(n_envs=n, vec_env=kind), errors)
                    envs.append(env)
                    env.reset()
                    actions = np.random.default_rng(n)

                    def block(env=env, n=n, actions=actions):
                        shape = (n, *env.action_space.shape)
                        for _ in range(-(-designs // n)):
                            rewards = env.step(actions.uniform(-1, 1, shape).astype(np.float32))[1]
                        return rewards

                    series[(f"train env, {names[kind]}, {n} envs", n, everything)] = block
            rows, found = interleaved_rates(series, designs, repeats)
    finally:
        for env in envs:
            env.close()
    values = list(found.values())
    for subproc, batched in zip(values[::2], values[1::2]):
        if not np.array_equal(subproc, batched):
            raise AssertionError("train env: the batched vector env's rewards differ from SubprocVecEnv's")
    return rows


def batch_user_rows(runs: int = 64, repeats: int = 5) -> list[list[dict]]:
    """Two users of the batch against their serial form (one design at a time, one
    thread), each a group of rows whose first is the serial figure: what `spreadgym
    reference --replicates RUNS` runs (`precision.reference_precisely`: `runs` paper runs
    through the batch, their replicate tray masses pooled, the pooled pattern's CV curve
    and standard errors), against `run_scene` run by run pooled and estimated the same
    way (`reference.reference_from`), and one CMA-ES
    generation on SpinnerDesign (the population `cma` asks for at the start, stepped as
    one batch by `step_designs`, against one design at a time). Designs per second, median
    of `repeats` interleaved blocks and their range; the block results are checked equal."""
    import cma
    import gymnasium as gym
    import numpy as np

    from spreadgym import threads
    from spreadgym.agents.evaluation import EvalContext
    from spreadgym.config.scene import load_scene
    from spreadgym.envs.vector import step_designs
    from spreadgym.physics.granules import replicate_sizes
    from spreadgym.spread.pipeline import run_scene
    from spreadgym.spread.precision import PooledMasses, PooledRuns, reference_precisely
    from spreadgym.spread.reference import reference_from
    from spreadgym.studies.benchmarks import interleaved_rates

    everything = threads.thread_count()
    scene = load_scene("paper")
    per_run = replicate_sizes(scene.sim.granules, scene.sim.replicates).size
    env = gym.make("spreadgym:SpinnerDesign-v0")
    dim = env.action_space.shape[0]
    population = [np.asarray(x) for x in cma.CMAEvolutionStrategy(np.zeros(dim), 0.5, {"seed": 1, "verbose": -9}).ask()]
    ctx = EvalContext(0, "compound-10-16-10", 4.0)
    resets = [(1000 + k, ctx.options()) for k in range(len(population))]

    def pooled_in_batches():
        found = reference_precisely(scene, runs=runs)
        return np.concatenate([found.pooled.pooled.masses().ravel(), found.cv_percent, found.cv_standard_error_percent])

    def pooled_one_by_one():
        pooled = PooledMasses(scene.pattern.tray_width_m)
        for j in range(runs):
            pooled.add(run_scene(scene, ci=False, first_replicate=j * per_run).replicate_masses_kg)
        replicates = pooled.masses().shape[0]
        found = reference_from(scene, PooledRuns(pooled, replicates, 0, 0, 0, 0.0, "", "", 0.0))
        return np.concatenate([pooled.masses().ravel(), found.cv_percent, found.cv_standard_error_percent])

    def generation_one_by_one():
        return [step_designs(env, [reset], [x])[0][1] for reset, x in zip(resets, population)]

    groups = {
        f"reference: {runs} paper runs pooled": (runs, [("run_scene, run by run", 1, pooled_one_by_one),
                                                       ("reference_precisely (batches)", runs, pooled_in_batches)]),
        f"CMA-ES generation on SpinnerDesign ({len(population)} designs)": (
            len(population), [("one design at a time", 1, generation_one_by_one),
                              ("step_designs (one batch)", len(population),
                               lambda: [step[1] for step in step_designs(env, resets, population)])]),
    }
    out = []
    for title, (designs, ways) in groups.items():
        series = {(f"{title}, {name}", size, n): run for name, size, run in ways
                  for n in ((1,) if size == 1 else sorted({1, everything}))}
        rows, found = interleaved_rates(series, designs, repeats)
        first, *others = found.values()
        if any(not np.array_equal(np.asarray(first), np.asarray(other), equal_nan=True) for other in others):
            raise AssertionError(f"{title}: the batch differs from one at a time")
        out.append(rows)
    env.close()
    return out
