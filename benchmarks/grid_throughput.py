"""Adversarial-training throughput of a grid of runs (1, 7, 35 cells) on Pendulum-v1.

For each grid size, builds the cells (1 = ``pngail`` x 1 seed, 7 = every method in
``METHOD_NAMES`` x 1 seed, 7k = every method x k seeds), compiles them into one
``pngail_jax.grid.Grid`` (``jit(vmap(train.init))`` and ``jit(vmap(train.run_blocks))``),
runs the init program (splits and classifier phase, not timed), one warm-up chunk, then times
3 warm chunk calls (median). A chunk is ``--iterations`` iterations (one block: eval_every =
iterations), each a rollout of num_envs x unroll_length steps, a discriminator step and a TRPO
update, followed by one evaluation of ``num_eval_episodes`` (32) episodes. Steps/s counts
training transitions of the real cells only: ``cells * iterations * num_envs * unroll_length /
seconds``; the evaluation episodes are excluded from the count but included in the time.

Compile seconds are the Grid's AOT compile (``grid.compile_seconds``: init + chunk programs);
peak memory is XLA's ``memory_analysis()`` of the compiled chunk program (arguments + outputs +
temporaries - aliased; per device when sharded). ``env_steps_per_second`` is environment-only
throughput at the same total width (num_envs x cells), measured in the same run with
``env_throughput.measure`` (on one device), giving ``train_over_env_ratio``;
``ratio_vs_one_cell`` divides by the 1-cell grid's steps/s in the same run (the gain from
batching cells). On a shared, noisy machine these same-run ratios are the numbers to trust.

Demonstrations: the authors' Pendulum set (``--demos``, default
``../shared/data/pendulum/Pendulum-v1_mixture.npy`` from the repository root, actions x 2);
if missing, 1000 random rows (throughput does not depend on their contents; the run says so).

    python benchmarks/grid_throughput.py --quick                  # 1, 7 cells: about 1 minute
    python benchmarks/grid_throughput.py --json rows.json         # 1, 7, 35 cells: about 5 min
    python benchmarks/grid_throughput.py --quick --devices 2      # sharded over 2 host devices

Runtimes are estimates for a quiet 2-core CPU, extrapolated from tiny runs (1 iteration per
chunk at full width: about 75,000 steps/s for 1 cell, 65,000 for 7; 8-17 s of compile per
grid), not measured at full size; a busy machine takes up to twice as long. The full run's
35-cell grid times 4 chunks of 35 x 10 x 5,000 steps (about 2 minutes), and its chunk program
should need about 1.4 GiB (7 cells: 274 MiB).

``--devices N`` shards every grid over N devices; on a CPU it re-runs this script in a
subprocess with ``XLA_FLAGS=--xla_force_host_platform_device_count=N`` (XLA reads it when its
backend starts). Grids are padded to a multiple of N with copies of their last cell, whose
steps are not counted; the env-only ceiling still runs on one device.

Row schema: env_throughput's ``{name, env, width, steps_per_second, compile_seconds,
peak_memory_bytes, device, jax_version}`` plus ``cells``, ``num_envs``, ``unroll_length``,
``iterations``, ``fisher``, ``env_steps_per_second``, ``train_over_env_ratio``,
``ratio_vs_one_cell`` (None without a 1-cell row), ``devices``, and ``methods``, ``seeds``,
``padded_cells``, ``init_compile_seconds``, ``chunk_compile_seconds``, ``init_peak_memory_bytes``,
``init_seconds`` (the untimed init call), ``nonfinite_cells``, ``synthetic_demos``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
from env_throughput import NUM_REPEATS, measure, peak_memory_bytes, scan_length
from trpo_throughput import device_description

from pngail_jax import envs
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.demos import Demonstrations, load_demonstrations
from pngail_jax.grid import Grid, make_cells, nonfinite_cells, stack_cells
from pngail_jax.methods import METHOD_NAMES
from pngail_jax.rl.train import TRPOConfig
from pngail_jax.train import AdversarialConfig, make_train

ENV_NAME = "Pendulum-v1"
REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DEMOS = REPO_ROOT.parent / "shared" / "data" / "pendulum" / "Pendulum-v1_mixture.npy"
DEMO_ACTION_SCALE = 2.0  # the released Pendulum set stores torques / 2
SYNTHETIC_ROWS = 1000
SIZES, QUICK_SIZES = (1, 7, 35), (1, 7)
CLASSIFIER_STEPS, QUICK_CLASSIFIER_STEPS = 25_000, 1_000


def grid_layout(size: int) -> tuple[tuple[str, ...], int]:
    """(methods, seeds) of a grid of ``size`` cells: pngail alone, or every method x seeds."""
    if size == 1:
        return ("pngail",), 1
    return METHOD_NAMES, size // len(METHOD_NAMES)


def load_demos(path: Path, env) -> tuple[Demonstrations, str]:
    """The released set at ``path``, or random rows of the right shapes if it is missing."""
    if path.exists():
        demos = load_demonstrations(path, action_scale=DEMO_ACTION_SCALE)
        return demos, f"{path.resolve()} ({demos.num_rows} rows)"
    rng = np.random.default_rng(0)
    low = np.broadcast_to(np.asarray(env.action_low), (env.action_size,))
    high = np.broadcast_to(np.asarray(env.action_high), (env.action_size,))
    demos = Demonstrations(
        observations=rng.standard_normal((SYNTHETIC_ROWS, env.observation_size), np.float32),
        actions=rng.uniform(low, high, (SYNTHETIC_ROWS, env.action_size)).astype(np.float32),
        confidence=rng.uniform(0.0, 1.0, SYNTHETIC_ROWS).astype(np.float32),
    )
    return demos, f"SYNTHETIC: {SYNTHETIC_ROWS} random rows ({path} not found)"


def measure_grid(train, size: int, devices, key: jax.Array) -> dict:
    """Compiles a grid of ``size`` cells and times warm chunk calls (median of NUM_REPEATS)."""
    methods, seeds = grid_layout(size)
    hyperparams, specs, keys = stack_cells(make_cells(methods, seeds), key)
    grid = Grid(train, hyperparams, specs, keys, blocks_per_chunk=1, devices=devices)
    start = time.perf_counter()
    state, _ = grid.init()
    jax.block_until_ready(state)
    init_seconds = time.perf_counter() - start
    state, metrics = grid.run_chunk(state)  # warm-up; run_chunk donates state: keep the new one
    jax.block_until_ready((state, metrics))
    timings = []
    for _ in range(NUM_REPEATS):
        start = time.perf_counter()
        state, metrics = grid.run_chunk(state)
        jax.block_until_ready((state, metrics))
        timings.append(time.perf_counter() - start)
    bad = nonfinite_cells(grid.fetch(metrics), grid.iterations_per_chunk)
    steps = grid.num_cells * grid.iterations_per_chunk * train.config.trpo.batch_size
    return {
        "steps_per_second": steps / statistics.median(timings),
        "compile_seconds": grid.compile_seconds,
        "peak_memory_bytes": peak_memory_bytes(grid.chunk_program),
        "methods": list(methods),
        "seeds": seeds,
        "padded_cells": grid.num_padded,
        "init_compile_seconds": grid.init_compile_seconds,
        "chunk_compile_seconds": grid.chunk_compile_seconds,
        "init_peak_memory_bytes": peak_memory_bytes(grid.init_program),
        "init_seconds": init_seconds,
        "nonfinite_cells": len(bad),
    }


def measure_rows(args, env, demos, devices, common: dict) -> list[dict]:
    config = AdversarialConfig(
        trpo=TRPOConfig(
            num_envs=args.num_envs,
            unroll_length=args.unroll_length,
            num_iterations=args.iterations,
            eval_every=args.iterations,
            fisher=args.fisher,
        ),
        classifier=ClassifierConfig(num_steps=args.classifier_steps),
        num_demos=None,
    )
    train = make_train(config, env, demos)
    key, rows = jax.random.key(args.seed), []
    for size in args.sizes:
        width = args.num_envs * size
        key, env_key, grid_key = jax.random.split(key, 3)
        env_speed = measure(env, width, scan_length(ENV_NAME, width, False), env_key)
        env_speed = env_speed["steps_per_second"]
        print(f"{size} cells, width {width}: env only {env_speed:,.0f} steps/s", flush=True)
        result = measure_grid(train, size, devices, grid_key)
        speed = result["steps_per_second"]
        layout = f"{len(result['methods'])}x{result['seeds']}"
        row = {"name": f"grid_train/{layout}", "env": ENV_NAME, "width": width, **result}
        row |= {
            **common,
            "cells": size,
            "num_envs": args.num_envs,
            "unroll_length": args.unroll_length,
            "iterations": args.iterations,
            "fisher": args.fisher,
            "env_steps_per_second": env_speed,
            "train_over_env_ratio": speed / env_speed,
            "ratio_vs_one_cell": None,
            "devices": len(devices),
        }
        rows.append(row)
        warning = ""
        if result["nonfinite_cells"]:
            warning = f"  WARNING: {result['nonfinite_cells']} cell(s) non-finite"
        print(
            f"  {size:3d} cells ({layout} methods x seeds) {speed:>10,.0f} steps/s  "
            f"compile {result['compile_seconds']:5.1f} s  init {result['init_seconds']:5.1f} s"
            f"{warning}",
            flush=True,
        )
    one_cell = [row["steps_per_second"] for row in rows if row["cells"] == 1]
    for row in rows:
        if one_cell:
            row["ratio_vs_one_cell"] = row["steps_per_second"] / one_cell[0]
    return rows


def markdown_table(rows: list[dict]) -> str:
    lines = [
        "| cells | steps/s | ratio vs one cell | env-only steps/s | train/env | compile s | "
        "peak memory MiB |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        memory = row["peak_memory_bytes"]
        memory = "-" if memory is None else f"{memory / 2**20:.1f}"
        ratio = row["ratio_vs_one_cell"]
        ratio = "-" if ratio is None else f"{ratio:.2f}"
        cells = row["cells"]
        if row["padded_cells"] != cells:
            cells = f"{cells} (padded to {row['padded_cells']})"
        lines.append(
            f"| {cells} | {row['steps_per_second']:,.0f} | {ratio} | "
            f"{row['env_steps_per_second']:,.0f} | {row['train_over_env_ratio']:.4f} | "
            f"{row['compile_seconds']:.1f} | {memory} |"
        )
    return "\n".join(lines)


def rerun_with_host_devices(num_devices: int, argv) -> int:
    """Runs this script again in a process whose CPU backend exposes ``num_devices`` devices."""
    flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count="
    environment = dict(os.environ, XLA_FLAGS=f"{flags}{num_devices}".strip())
    argv = sys.argv[1:] if argv is None else list(argv)
    command = [sys.executable, str(Path(__file__).resolve()), *argv, "--devices-worker"]
    print(f"re-running with {num_devices} host devices: XLA_FLAGS={environment['XLA_FLAGS']}")
    return subprocess.run(command, env=environment).returncode


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
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
        help="iterations per timed chunk (= eval_every; default 10)",
    )
    parser.add_argument(
        "--num-envs", type=int, default=25, help="parallel envs per cell (default 25)"
    )
    parser.add_argument(
        "--unroll-length", type=int, default=200, help="steps per env per rollout (default 200)"
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
        choices=("hessian", "gauss_newton"),
        default="gauss_newton",
        help="Fisher-vector product form (default gauss_newton, as experiments.sweep)",
    )
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
        default=DEFAULT_DEMOS,
        help="released *_mixture.npy (default ../shared/data/pendulum/Pendulum-v1_mixture.npy "
        "from the repository root; random rows if missing)",
    )
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    parser.add_argument("--seed", type=int, default=0, help="key of cells and env runs")
    parser.add_argument("--devices-worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
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
    for name in ("iterations", "num_envs", "unroll_length", "classifier_steps"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be a positive integer")
    if args.devices is not None and args.devices < 1:
        parser.error("--devices must be a positive integer")
    return args


def main(argv=None) -> None:
    args = parse_args(argv)
    num_devices = args.devices or 1
    if jax.device_count() < num_devices:
        if args.devices_worker or jax.devices()[0].platform != "cpu":
            raise SystemExit(f"--devices {num_devices}: jax sees only {jax.devices()}")
        raise SystemExit(rerun_with_host_devices(num_devices, argv))
    devices = jax.devices()[:num_devices]
    common = {"device": device_description(), "jax_version": jax.__version__}
    print(
        f"device {common['device']} x{num_devices} used, jax {jax.__version__}; {ENV_NAME}, "
        f"{args.num_envs} envs x {args.unroll_length} steps per cell-iteration, "
        f"{args.iterations} iterations per timed chunk, {args.classifier_steps:,} classifier "
        "steps (untimed)",
        flush=True,
    )
    env = envs.make(ENV_NAME)
    demos, demos_note = load_demos(args.demos, env)
    print(f"demonstrations: {demos_note}", flush=True)
    common["synthetic_demos"] = demos_note.startswith("SYNTHETIC")
    rows = measure_rows(args, env, demos, devices, common)
    per_device = "; peak memory per device" if num_devices > 1 else ""
    print(
        f"\ndemonstrations: {demos_note}\n{ENV_NAME}; {args.num_envs} envs x "
        f"{args.unroll_length} steps x {args.iterations} iterations per cell per timed call "
        f"(+ one {TRPOConfig.num_eval_episodes}-episode evaluation, timed, not counted); "
        f"median of {NUM_REPEATS} warm calls; {num_devices} device(s){per_device}.\n"
    )
    print(markdown_table(rows), flush=True)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=2))
        print(f"\nwrote {args.json}", file=sys.stderr)


if __name__ == "__main__":
    main()
