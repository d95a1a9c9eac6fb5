"""Adversarial-training throughput of a grid of runs (1, 7, 35 cells) on one environment.

``--env NAME`` (default Pendulum-v1) runs with that task's row of ``pngail_jax.config.settings``
(parallel envs x unroll length, MJX solver, evaluation episodes and frequency); the run-settings
flags (``--num-envs``, ``--unroll-length``, ``--solver``, ``--eval-every``, ...) override it.

For each grid size, builds the cells (1 = ``pngail`` x 1 seed, 7 = every method in
``METHOD_NAMES`` x 1 seed, 7k = every method x k seeds) and compiles them into one
``pngail_jax.grid.Grid`` (``jit(vmap(trainer.init))`` and ``jit(vmap(trainer.run_blocks))``). It
runs the init program (splits and classifier phase, untimed), one warm-up chunk, then times 3
warm chunk calls (median). A chunk is ``--iterations`` iterations (eval_every = iterations),
each a rollout of num_envs x unroll_length steps per cell, a discriminator step and a TRPO
update, then one evaluation of every cell. The evaluation alone, ``jit(vmap(trpo.evaluate))``
over the final state's policies and evaluation keys, is timed the same way, so

    iteration_seconds = (chunk_seconds - eval_seconds) / iterations
    steps_per_second = cells * num_envs * unroll_length / iteration_seconds   (training only)

and at the settings' evaluation frequency E (``eval_every``, not the chunk's):

    eval_share = eval_seconds / (E * iteration_seconds + eval_seconds)
    steps_per_second_with_eval = E * cells * num_envs * unroll_length
                                 / (E * iteration_seconds + eval_seconds)

An evaluation stops once every episode of every cell has ended. The cells' policies are barely
trained here, and on Ant, Hopper and Walker2d their episodes end early (the body falls), so
``eval_share`` is a lower bound; ``eval_share_full_episodes`` times the same evaluation on the
task built with ``terminate_when_unhealthy=False`` (every episode runs ``max_episode_steps``),
the most a trained policy's evaluation can cost. HalfCheetah, Swimmer and Pendulum-v1 never
end an episode early: there both are one measurement.

``env_steps_per_second`` is environment-only throughput (``env_throughput.measure``) at the
same total width (num_envs x cells) with the same solver, on one device, measured in the same
run; ``train_over_env_ratio`` = steps_per_second / env_steps_per_second, and
``ratio_vs_one_cell`` divides steps_per_second by the 1-cell grid's (the gain from batching
cells). On a shared, noisy machine these same-run ratios are the numbers to trust.

Compile seconds are the Grid's AOT compile (tracing, lowering and XLA; init + chunk programs)
with JAX's persistent compilation cache
(``pngail_jax.storage.compilation.enable_compilation_cache``, which stores programs that take at
least 1 s to compile), each in a fresh Python process (this script with ``--compile-worker``)
that builds the grid as the measurement does: the cold compile on a new, empty temporary
directory (``compile_seconds``), then the warm one on the directory it filled
(``compile_seconds_warm``), as a repeated command would; ``cold_cache_hits`` (0 expected) and
``warm_cache_hits`` (2 expected) count the programs read from the directory.
Fresh processes because a rebuild in the same process need not lower to the same program: the
names of the lowered inner functions depend on the state of JAX's trace caches (``_take_116``
the first time, ``_take_118`` after another program was traced), and on Hopper an in-process
rebuild missed the disk cache. (JAX keeps no in-memory copy of a compiled program for new jit
objects: a Pendulum-v1 rebuild in the same process reads both programs from disk.) The
measuring process compiles its own grid again, without the cache. Peak memory is XLA's
``memory_analysis()`` of the compiled chunk program (arguments + outputs + temporaries -
aliased; per device when sharded).

Demonstrations (their contents do not change the throughput): ``--demos``, by default the
authors' Pendulum set ``data/released/Pendulum-v1_mixture.npy`` in the repository (a download,
see docs/demonstrations.md; actions x 2) for Pendulum-v1 and none for the MuJoCo tasks;
without a file, 1000 random rows of the task's shapes (the run says so).

    python benchmarks/grid_throughput.py --quick                  # Pendulum-v1, 1 and 7 cells
    python benchmarks/grid_throughput.py --json rows.json         # Pendulum-v1, 1, 7, 35 cells
    python benchmarks/grid_throughput.py --env Hopper --quick --json hopper.json
    python benchmarks/grid_throughput.py --quick --devices 2      # sharded over 2 host devices
    python benchmarks/grid_throughput.py --env HalfCheetah-v4 --physics c,mjx --sizes 7

``--physics c,mjx`` measures gymnasium's task on MuJoCo's C engine and on MJX one after the
other in this run and ends with a side-by-side table: training and env-only steps/s per engine
and the C engine's ratio over MJX at each grid size (rows gain ``physics``). ``--learner
trpo,ppo`` does the same for the policy learner under every method (rows gain ``learner``;
one of the two flags may list several values).

    python benchmarks/grid_throughput.py --env HalfCheetah-v4 --learner trpo,ppo --sizes 1,7

``--devices N`` shards every grid over N devices; on a CPU it re-runs this script in a
subprocess with ``XLA_FLAGS=--xla_force_host_platform_device_count=N`` (XLA reads it when its
backend starts). Grids are padded to a multiple of N with copies of their last cell, whose
steps are not counted; the env-only ceiling still runs on one device.

Row schema: env_throughput's ``{name, env, width, steps_per_second, compile_seconds,
peak_memory_bytes, device, jax_version}`` plus ``cells``, ``num_envs``, ``unroll_length``,
``iterations``, ``fisher``, ``settings`` (the ``RunSettings`` fields), ``env_steps_per_second``,
``train_over_env_ratio``, ``ratio_vs_one_cell`` (None without a 1-cell row), ``devices``,
``methods``, ``seeds``, ``padded_cells``, ``chunk_seconds``, ``iteration_seconds``,
``eval_seconds``, ``eval_seconds_full_episodes``, ``eval_share``, ``eval_share_full_episodes``,
``steps_per_second_with_eval``, ``steps_per_second_with_full_eval``, ``init_compile_seconds``,
``chunk_compile_seconds``, ``cold_cache_hits``, ``compile_seconds_warm``,
``init_compile_seconds_warm``, ``chunk_compile_seconds_warm``, ``warm_cache_hits``,
``init_peak_memory_bytes``, ``init_seconds`` (the untimed init call), ``nonfinite_cells``,
``synthetic_demos``, ``physics`` (the engine of gymnasium's tasks, else None), ``learner``.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import jax
import numpy as np
from common import (
    NUM_REPEATS,
    context,
    env_ceiling,
    markdown_table,
    mebibytes,
    median_seconds,
    peak_memory_bytes,
    scan_length,
    time_grid_chunks,
    write_rows,
)  # fmt: skip
from jax import monitoring

from pngail_jax import envs
from pngail_jax.adversarial.family import ADVERSARIAL
from pngail_jax.adversarial.methods import METHOD_NAMES
from pngail_jax.adversarial.trainer import AdversarialConfig, AdversarialTrainer, TrainState
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.config import settings as env_settings
from pngail_jax.config.learner import DEFAULT_FISHER, FISHER_FORMS, LEARNERS, LearnerConfig
from pngail_jax.demos import Demonstrations, load_demonstrations
from pngail_jax.grid import Grid, make_cells, nonfinite_cells, stack_cells
from pngail_jax.programs import flags
from pngail_jax.rl.trpo import TRPO, TRPOConfig
from pngail_jax.storage.compilation import enable_compilation_cache

DEFAULT_ENV = "Pendulum-v1"
REPO_ROOT = Path(__file__).resolve().parents[1]
PENDULUM_DEMOS = REPO_ROOT / "data" / "pendulum" / "Pendulum-v1_mixture.npy"
PENDULUM_ACTION_SCALE = 2.0  # the released Pendulum set stores torques / 2
SYNTHETIC_ROWS = 1000
# Tasks that end an episode when the body falls (terminate_when_unhealthy).
TERMINATING_TASKS = ("Ant", "Hopper", "Walker2d", "Ant-v4", "Hopper-v4", "Walker2d-v4")
SIZES, QUICK_SIZES = (1, 7, 35), (1, 7)
CLASSIFIER_STEPS, QUICK_CLASSIFIER_STEPS = 25_000, 1_000
CACHE_HIT_EVENT = "/jax/compilation_cache/cache_hits"


def grid_layout(size: int) -> tuple[tuple[str, ...], int]:
    """(methods, seeds) of a grid of ``size`` cells: pngail alone, or every method x seeds."""
    if size == 1:
        return ("pngail",), 1
    return METHOD_NAMES, size // len(METHOD_NAMES)


def load_demos(path: Path | None, env_name: str, env) -> tuple[Demonstrations, str]:
    """The set at ``path``, or random rows of the task's shapes without one."""
    if path is not None and path.exists():
        action_scale = PENDULUM_ACTION_SCALE if env_name == "Pendulum-v1" else 1.0
        demos = load_demonstrations(path, action_scale=action_scale)
        return demos, f"{path.resolve()} ({demos.num_rows} rows)"
    rng = np.random.default_rng(0)
    low = np.broadcast_to(np.asarray(env.action_low), (env.action_size,))
    high = np.broadcast_to(np.asarray(env.action_high), (env.action_size,))
    demos = Demonstrations(
        observations=rng.standard_normal((SYNTHETIC_ROWS, env.observation_size), np.float32),
        actions=rng.uniform(low, high, (SYNTHETIC_ROWS, env.action_size)).astype(np.float32),
        confidence=rng.uniform(0.0, 1.0, SYNTHETIC_ROWS).astype(np.float32),
    )
    reason = "no demonstration file" if path is None else f"{path} not found"
    return demos, f"SYNTHETIC: {SYNTHETIC_ROWS} random rows ({reason})"


def full_episode_trpo(env_name: str, settings, train, cells: int) -> TRPO | None:
    """``train``'s TRPO on the task without early termination; None where it never ends one."""
    if env_name not in TERMINATING_TASKS:
        return None
    options = dict(settings.env_options)
    if env_name in envs.GYM_TASKS:
        options["physics"] = settings.physics
        if settings.physics == "warp":
            options["warp_batch"] = cells * max(settings.num_envs, settings.num_eval_episodes)
    env = envs.make(env_name, terminate_when_unhealthy=False, **options)
    return TRPO(train.config.rollout, env, train.config.learner.trpo)


@contextlib.contextmanager
def counting_cache_hits():
    """Yields a list that collects one entry per persistent-compilation-cache hit."""
    hits = []

    def listener(event: str, **_) -> None:
        if event == CACHE_HIT_EVENT:
            hits.append(event)

    monitoring.register_event_listener(listener)
    try:
        yield hits
    finally:
        monitoring.unregister_event_listener(listener)


def evaluation_seconds(trpo: TRPO, state: TrainState) -> float:
    """Median seconds of one evaluation of every cell of ``state`` with ``trpo``'s env."""
    evaluate = jax.jit(jax.vmap(trpo.evaluate))
    program = evaluate.lower(state.learner, state.eval_keys).compile()
    return median_seconds(program, state.learner, state.eval_keys)


def time_chunks(grid: Grid) -> tuple[TrainState, dict]:
    """Runs init and a warm-up chunk, then times NUM_REPEATS chunks (median); returns the
    final state and the timings."""
    state, metrics, init_seconds, chunk_seconds = time_grid_chunks(grid)
    bad = nonfinite_cells(grid.fetch(metrics), grid.iterations_per_chunk)
    return state, {
        "chunk_seconds": chunk_seconds,
        "init_seconds": init_seconds,
        "nonfinite_cells": len(bad),
    }


def evaluation_costs(
    chunk_seconds: float,
    eval_seconds: float,
    eval_seconds_full_episodes: float,
    iterations: int,
    eval_every: int,
    steps_per_iteration: int,
) -> dict:
    """Training-only steps/s, and the evaluation's share at one evaluation per ``eval_every``
    iterations, for the measured (untrained) and full-length episodes."""
    iteration_seconds = (chunk_seconds - eval_seconds) / iterations
    if iteration_seconds <= 0:
        raise SystemExit(
            f"the evaluation ({eval_seconds:.3f} s) took longer than a whole chunk "
            f"({chunk_seconds:.3f} s): use more --iterations"
        )
    training_seconds = eval_every * iteration_seconds
    block_steps = eval_every * steps_per_iteration
    full_block_seconds = training_seconds + eval_seconds_full_episodes
    return {
        "steps_per_second": steps_per_iteration / iteration_seconds,
        "iteration_seconds": iteration_seconds,
        "steps_per_second_with_eval": block_steps / (training_seconds + eval_seconds),
        "steps_per_second_with_full_eval": block_steps / full_block_seconds,
        "eval_share": eval_seconds / (training_seconds + eval_seconds),
        "eval_share_full_episodes": eval_seconds_full_episodes / full_block_seconds,
    }


def compile_in_fresh_process(args, size: int, cache_dir: str) -> dict:
    """Compile seconds of the grid of ``size`` cells in a new Python process (this script with
    the same flags and ``--compile-worker``) whose compilation cache is ``cache_dir``."""
    command = [sys.executable, str(Path(__file__).resolve()), *args.argv]
    command += ["--compile-worker", str(size), "--cache-dir", cache_dir]
    result = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=True)
    return json.loads(result.stdout.splitlines()[-1])


def compile_worker(args, devices) -> None:
    """Builds the grid of ``args.compile_worker`` cells as ``measure_grid`` does, with the
    compilation cache in ``args.cache_dir``, and prints its compile seconds and cache hits."""
    enable_compilation_cache(args.cache_dir)
    env = env_settings.make_env(args.env, args.env_settings, cells=args.compile_worker)
    demos, _ = load_demos(args.demos, args.env, env)
    train = make_grid_train(args, env, demos)
    methods, seeds = grid_layout(args.compile_worker)
    inputs = stack_cells(
        make_cells(methods, seeds),
        jax.random.key(args.seed),
        learner=args.learner,
        family=ADVERSARIAL,
    )
    with counting_cache_hits() as hits:
        grid = Grid(train, inputs, blocks_per_chunk=1, devices=devices)
    times = {
        "compile_seconds": grid.compile_seconds,
        "init_compile_seconds": grid.init_compile_seconds,
        "chunk_compile_seconds": grid.chunk_compile_seconds,
        "cache_hits": len(hits),
    }
    print(json.dumps(times), flush=True)


def compile_times(args, size: int) -> dict:
    """Cold (empty cache) then warm (the cache the cold compile filled) compile of the grid of
    ``size`` cells, each in a fresh process; with ``--no-compile-times``, only the measuring
    process's own compile (no cache), as ``compile_seconds``."""
    if not args.compile_times:
        return {"compile_seconds": None, "compile_seconds_warm": None, "warm_cache_hits": None}
    print("  compiling in two fresh processes (cold, then warm)", flush=True)
    with tempfile.TemporaryDirectory(prefix="grid_throughput_xla_cache_") as cache_dir:
        cold = compile_in_fresh_process(args, size, cache_dir)
        warm = compile_in_fresh_process(args, size, cache_dir)
    return {
        "compile_seconds": cold["compile_seconds"],
        "init_compile_seconds": cold["init_compile_seconds"],
        "chunk_compile_seconds": cold["chunk_compile_seconds"],
        "cold_cache_hits": cold["cache_hits"],
        "compile_seconds_warm": warm["compile_seconds"],
        "init_compile_seconds_warm": warm["init_compile_seconds"],
        "chunk_compile_seconds_warm": warm["chunk_compile_seconds"],
        "warm_cache_hits": warm["cache_hits"],
    }


def measure_grid(args, train, full_trpo, size: int, devices, key) -> dict:
    """Compile seconds (``compile_times``) of the grid of ``size`` cells, then its chunk and
    evaluation timings in this process."""
    compiling = compile_times(args, size)
    methods, seeds = grid_layout(size)
    inputs = stack_cells(make_cells(methods, seeds), key, learner=args.learner, family=ADVERSARIAL)
    grid = Grid(train, inputs, blocks_per_chunk=1, devices=devices)
    if compiling["compile_seconds"] is None:
        compiling["compile_seconds"] = grid.compile_seconds
    state, chunks = time_chunks(grid)
    eval_seconds = evaluation_seconds(train.learner, state)
    eval_seconds_full = eval_seconds if full_trpo is None else evaluation_seconds(full_trpo, state)
    costs = evaluation_costs(
        chunks["chunk_seconds"],
        eval_seconds,
        eval_seconds_full,
        grid.iterations_per_chunk,
        args.env_settings.eval_every,
        grid.num_cells * train.config.rollout.batch_size,
    )
    return {
        **costs,
        "peak_memory_bytes": peak_memory_bytes(grid.chunk_program),
        "methods": list(methods),
        "seeds": seeds,
        "padded_cells": grid.num_padded,
        **chunks,
        "eval_seconds": eval_seconds,
        "eval_seconds_full_episodes": eval_seconds_full,
        **compiling,
        "init_peak_memory_bytes": peak_memory_bytes(grid.init_program),
    }


def make_grid_train(args, env, demos):
    """The adversarial trainer of one chunk: ``--iterations`` iterations, one evaluation."""
    chunk_settings = args.env_settings.replace(eval_every=args.iterations)
    config = AdversarialConfig(
        rollout=chunk_settings.rollout_config(args.iterations),
        learner=LearnerConfig(name=args.learner, trpo=TRPOConfig(fisher=args.fisher)),
        classifier=ClassifierConfig(num_steps=args.classifier_steps),
        num_demos=None,
    )
    return AdversarialTrainer(config, env, demos)


def measure_rows(args, env, demos, devices, common: dict) -> list[dict]:
    settings = args.env_settings
    train = make_grid_train(args, env, demos)
    full_trpo = full_episode_trpo(args.env, settings, train, max(args.sizes))
    key, rows = jax.random.key(args.seed), []
    for size in args.sizes:
        width = settings.num_envs * size
        key, env_key, grid_key = jax.random.split(key, 3)
        env_speed = env_ceiling(env, width, scan_length(args.env, width, False), env_key)
        env_speed = env_speed["steps_per_second"]
        print(f"{size} cells, width {width}: env only {env_speed:,.0f} steps/s", flush=True)
        result = measure_grid(args, train, full_trpo, size, devices, grid_key)
        speed = result["steps_per_second"]
        layout = f"{len(result['methods'])}x{result['seeds']}"
        row = {"name": f"grid_train/{layout}", "env": args.env, "width": width, **result}
        row |= {
            **common,
            "cells": size,
            "num_envs": settings.num_envs,
            "unroll_length": settings.unroll_length,
            "iterations": args.iterations,
            "fisher": args.fisher,
            "settings": dataclasses.asdict(settings),
            "env_steps_per_second": env_speed,
            "train_over_env_ratio": speed / env_speed,
            "ratio_vs_one_cell": None,
            "devices": len(devices),
        }
        rows.append(row)
        print_progress(row)
    one_cell = [row["steps_per_second"] for row in rows if row["cells"] == 1]
    for row in rows:
        if one_cell:
            row["ratio_vs_one_cell"] = row["steps_per_second"] / one_cell[0]
    return rows


def print_progress(row: dict) -> None:
    warning = ""
    if row["nonfinite_cells"]:
        warning = f"  WARNING: {row['nonfinite_cells']} cell(s) non-finite"
    if row["warm_cache_hits"] is not None and row["warm_cache_hits"] < 2:
        warning += f"  NOTE: warm compile read {row['warm_cache_hits']} of 2 programs from cache"
    print(
        f"  {row['cells']:3d} cells ({len(row['methods'])}x{row['seeds']} methods x seeds) "
        f"{row['steps_per_second']:>10,.0f} steps/s training, "
        f"{row['steps_per_second_with_eval']:>10,.0f} with evaluation  "
        f"compile {row['compile_seconds']:5.1f} s cold, "
        f"{_seconds(row['compile_seconds_warm'])} warm"
        f"  init {row['init_seconds']:5.1f} s{warning}",
        flush=True,
    )


def _seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f} s"


def rows_table(rows: list[dict]) -> str:
    header = [
        "cells", "steps/s training", "steps/s incl. eval (untrained / full episodes)",
        "env-only steps/s", "train/env", "eval share (untrained / full episodes)",
        "compile s cold / warm", "peak memory MiB",
    ]  # fmt: skip
    cells = []
    for row in rows:
        size = row["cells"]
        if row["padded_cells"] != size:
            size = f"{size} (padded to {row['padded_cells']})"
        cells.append([
            size, f"{row['steps_per_second']:,.0f}",
            f"{row['steps_per_second_with_eval']:,.0f} / "
            f"{row['steps_per_second_with_full_eval']:,.0f}",
            f"{row['env_steps_per_second']:,.0f}", f"{row['train_over_env_ratio']:.4f}",
            f"{row['eval_share']:.1%} / {row['eval_share_full_episodes']:.1%}",
            f"{row['compile_seconds']:.1f} / {_seconds(row['compile_seconds_warm'])}",
            mebibytes(row["peak_memory_bytes"]),
        ])  # fmt: skip
    return markdown_table(header, cells, "rrrrrrrr")


def rerun_with_host_devices(num_devices: int, argv) -> int:
    """Runs this script again in a process whose CPU backend exposes ``num_devices`` devices."""
    flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count="
    environment = dict(os.environ, XLA_FLAGS=f"{flags}{num_devices}".strip())
    argv = sys.argv[1:] if argv is None else list(argv)
    command = [sys.executable, str(Path(__file__).resolve()), *argv, "--devices-worker"]
    print(f"re-running with {num_devices} host devices: XLA_FLAGS={environment['XLA_FLAGS']}")
    return subprocess.run(command, env=environment).returncode


def _add_grid_flags(parser: argparse.ArgumentParser) -> None:
    """What each grid is: its task, sizes, chunk, classifier, Fisher form and learner."""
    parser.add_argument(
        "--env",
        choices=envs.ENV_NAMES,
        default=DEFAULT_ENV,
        help=f"environment (default {DEFAULT_ENV})",
    )
    parser.add_argument(
        "--sizes",
        default=None,
        help="comma-separated cell counts: 1 or multiples of 7 "
        f"(default {','.join(map(str, SIZES))})",
    )
    parser.add_argument(
        "--iterations",
        type=int,
        default=10,
        help="iterations per timed chunk, which ends with one evaluation (default 10)",
    )
    parser.add_argument(
        "--classifier-steps",
        type=int,
        default=None,
        help=f"confidence-classifier steps in the untimed init (default {CLASSIFIER_STEPS:,}; "
        f"--quick {QUICK_CLASSIFIER_STEPS:,})",
    )
    parser.add_argument(
        "--fisher",
        choices=FISHER_FORMS,
        default=DEFAULT_FISHER,
        help="Fisher-vector product form (default gauss_newton, as experiments.sweep)",
    )
    parser.add_argument(
        "--learner",
        choices=LEARNERS,
        default="trpo",
        help="the policy learner under every method (default trpo); trpo,ppo measures both "
        "in this run, side by side",
    )


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    _add_grid_flags(parser)
    parser.add_argument("--devices", type=int, default=None, help="shard every grid over N devices")
    parser.add_argument(
        "--quick",
        action="store_true",
        help=f"sizes {','.join(map(str, QUICK_SIZES))} and a {QUICK_CLASSIFIER_STEPS:,}-step "
        "classifier (explicit options still win)",
    )
    parser.add_argument(
        "--demos",
        type=Path,
        default=None,
        help="demonstration file (default for Pendulum-v1: "
        "data/released/Pendulum-v1_mixture.npy in the repository, if downloaded; random rows "
        "without a file)",
    )
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    parser.add_argument(
        "--compile-times",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="time the cold and warm compiles in two fresh processes (default); "
        "--no-compile-times reports only this process's compile, and saves two compiles",
    )
    parser.add_argument("--seed", type=int, default=0, help="key of cells and env runs")
    parser.add_argument("--devices-worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--compile-worker", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--cache-dir", help=argparse.SUPPRESS)
    flags.add_settings_flags(parser)
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    return _checked(parser, args)


def _checked(parser: argparse.ArgumentParser, args: argparse.Namespace) -> argparse.Namespace:
    """The flags' values resolved (sizes, classifier steps, demonstrations, settings) and
    checked, naming the flag of a bad one."""
    if args.sizes is None:
        args.sizes = QUICK_SIZES if args.quick else SIZES
    else:
        try:
            args.sizes = tuple(int(size) for size in args.sizes.split(",") if size.strip())
        except ValueError:
            parser.error(f"--sizes must be comma-separated integers, got {args.sizes!r}")
    bad = [s for s in args.sizes if not (s == 1 or (s > 0 and s % len(METHOD_NAMES) == 0))]
    if bad or not args.sizes:
        parser.error(f"--sizes must be 1 or multiples of {len(METHOD_NAMES)}, got {bad}")
    if args.classifier_steps is None:
        args.classifier_steps = QUICK_CLASSIFIER_STEPS if args.quick else CLASSIFIER_STEPS
    for name in ("iterations", "classifier_steps"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be a positive integer")
    if args.devices is not None and args.devices < 1:
        parser.error("--devices must be a positive integer")
    if args.demos is None and args.env == "Pendulum-v1" and PENDULUM_DEMOS.exists():
        args.demos = PENDULUM_DEMOS
    args.env_settings = flags.settings_from_flags(parser, args, args.env)
    return args


def measure_environment(args, devices) -> list[dict]:
    """Builds the task and its demonstrations and measures every grid size."""
    settings = args.env_settings
    env = env_settings.make_env(args.env, settings, cells=max(args.sizes))
    demos, demos_note = load_demos(args.demos, args.env, env)
    print(
        f"device {context()['device']} x{len(devices)} used, jax {jax.__version__}; "
        f"{args.env}: {env_settings.describe(settings, env)}; {args.iterations} iterations per "
        f"timed chunk, {args.classifier_steps:,} classifier steps (untimed)\n"
        f"demonstrations: {demos_note}",
        flush=True,
    )
    common = {
        **context(),
        "synthetic_demos": demos_note.startswith("SYNTHETIC"),
        "physics": getattr(env, "physics", None),
        "learner": args.learner,
    }
    rows = measure_rows(args, env, demos, devices, common)
    per_device = "; peak memory per device" if len(devices) > 1 else ""
    print(
        f"\n{args.env}: {env_settings.describe(settings, env)}; demonstrations: {demos_note}\n"
        f"Timed: median of {NUM_REPEATS} warm calls of a chunk ({args.iterations} iterations + "
        "one evaluation) and of an evaluation alone; training steps/s leaves the evaluation "
        f"out, 'incl. eval' adds one every {settings.eval_every} iterations; {len(devices)} "
        f"device(s){per_device}.\n"
    )
    return rows


# The flags that may list several values, each measured in turn in one run: {flag: choices}.
COMPARED_FLAGS = {"physics": envs.PHYSICS, "learner": LEARNERS}


def split_compared(argv: list[str], name: str) -> tuple[list[str], list[str | None]]:
    """``argv`` without its ``--<name>`` flag, and the values that flag lists (``c,mjx``:
    both, measured one after the other in this run; no flag: [None], the default)."""
    rest, values, known = [], [None], COMPARED_FLAGS[name]
    items = iter(argv)
    for item in items:
        if item == f"--{name}" or item.startswith(f"--{name}="):
            value = item.partition("=")[2] if "=" in item else next(items, "")
            values = [choice.strip() for choice in value.split(",")]
            bad = [choice for choice in values if choice not in known]
            if bad or not values:
                raise SystemExit(
                    f"--{name}: comma-separated values among {', '.join(known)}, got {value!r}"
                )
        else:
            rest.append(item)
    return rest, values


def side_by_side_table(rows: list[dict], name: str) -> str:
    """Training and env-only steps/s per value of ``name`` (a row field: physics, learner),
    side by side per grid size, with the ratios of the first value listed over each other
    one (all measured in this run)."""
    engines = list(dict.fromkeys(row[name] for row in rows))
    sizes = list(dict.fromkeys(row["cells"] for row in rows))
    first = engines[0]
    header = "| cells | " + " | ".join(
        f"{engine}: training / env-only steps/s" for engine in engines
    )
    header += "".join(f" | {first} / {other}: training, env-only" for other in engines[1:])
    lines = [header + " |", "|---:|" + "---:|" * (2 * len(engines) - 1)]
    for size in sizes:
        by_engine = {row[name]: row for row in rows if row["cells"] == size}
        cells = [
            f"{by_engine[e]['steps_per_second']:,.0f} / {by_engine[e]['env_steps_per_second']:,.0f}"
            for e in engines
        ]
        for other in engines[1:]:
            a, b = by_engine[first], by_engine[other]
            cells.append(
                f"{a['steps_per_second'] / b['steps_per_second']:.1f}x, "
                f"{a['env_steps_per_second'] / b['env_steps_per_second']:.1f}x"
            )
        lines.append(f"| {size} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    compared = {}
    for name in COMPARED_FLAGS:
        rest, values = split_compared(argv, name)
        if len(values) > 1:
            compared[name] = (rest, values)
    if len(compared) > 1:
        raise SystemExit("--physics and --learner: list several values for one of them only")
    if compared and "--devices" in " ".join(argv):
        raise SystemExit("several --physics or --learner values and --devices: one at a time")
    if compared:
        ((name, (rest, values)),) = compared.items()
        rows = []
        for value in values:
            print(f"\n=== {name}: {value}", flush=True)
            rows += run(rest + [f"--{name}", value])
        print("\n" + side_by_side_table(rows, name), flush=True)
    else:
        rest, rows = argv, run(argv)
    if rows:
        write_rows(parse_args(rest).json, rows)


def run(argv: list[str]) -> list[dict]:
    """Measures one engine (or the platform's): this script's rows for ``argv``."""
    args = parse_args(argv)
    num_devices = args.devices or 1
    if jax.device_count() < num_devices:
        if args.devices_worker or jax.devices()[0].platform != "cpu":
            raise SystemExit(f"--devices {num_devices}: jax sees only {jax.devices()}")
        code = rerun_with_host_devices(num_devices, argv)
        if code:
            raise SystemExit(code)
        return []
    devices = jax.devices()[:num_devices]
    if args.compile_worker:
        compile_worker(args, devices)
        return []
    rows = measure_environment(args, devices)
    print(rows_table(rows), flush=True)
    return rows


if __name__ == "__main__":
    main()
