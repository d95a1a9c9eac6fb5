"""TRPO training throughput, and its ratio to environment-only throughput at the same width.

Times one compiled ``jit(vmap(run))`` over seeds, where ``run`` is a ``lax.scan`` of
``--iterations`` TRPO iterations (``trpo.rollout`` + ``trpo.update``; no evaluation), warm,
median of 3 calls. Steps/s counts training transitions only:
``iterations * num_envs * unroll_length * seeds / seconds``. Compile seconds are lower plus
compile; peak memory is XLA's ``memory_analysis()`` (arguments + outputs + temporaries -
aliased). ``train_over_env_ratio`` divides by environment-only steps/s at the same total width
(num_envs * seeds), measured in the same run with ``env_throughput.measure``. Rows: reference
fidelity (``TRPOConfig(fisher="hessian")``: Hessian Fisher products on every sample) and the
speed options ``fisher="gauss_newton"``, ``fisher_subsample=5`` and both. Pendulum-v1 runs
the reference's 25 envs x 200 steps; Brax tasks 16 x 64 so that a CPU finishes.

    python benchmarks/trpo_throughput.py --quick                 # Pendulum, seeds 1,5, 2 rows
    python benchmarks/trpo_throughput.py --brax-seeds 1,5 --json rows.json  # 8 min, 2-core CPU
    python benchmarks/trpo_throughput.py --devices 2             # only the sharding study

``--devices N``: Pendulum-v1, reference fidelity, 5N seeds on one device in this process, then
in a subprocess with N host devices (XLA_FLAGS), on one of them and sharded over the seed axis.
Row schema: env_throughput's plus ``seeds``, ``num_envs``, ``unroll_length``, ``fisher``,
``fisher_subsample``, ``env_steps_per_second``, ``train_over_env_ratio``,
``speedup_vs_reference`` (sharding rows: ``setting``, ``devices``, ``ratio_vs_plain``; a
sharded row's peak memory is per device).
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
from common import (
    NUM_REPEATS,
    context,
    env_ceiling,
    markdown_table,
    mebibytes,
    peak_memory_bytes,
    scan_length,
    write_rows,
)  # fmt: skip

from pngail_jax import envs
from pngail_jax.rl.on_policy import RolloutConfig
from pngail_jax.rl.trpo import TRPO, TRPOConfig, TRPOHyperparams

REFERENCE_SPEED = 4400.0  # the authors' PyTorch TRPO on Pendulum-v1, one core, training only
REFERENCE_NOTE = (
    "vs reference 4,400 steps/s (measured by the project on this machine type, not in this "
    "run; a Pendulum-v1 figure, so for other envs it only sets a scale)"
)
VARIANTS = {
    "reference": {"fisher": "hessian"},
    "gauss_newton": {"fisher": "gauss_newton"},
    "subsample5": {"fisher": "hessian", "fisher_subsample": 5},
    "gauss_newton+subsample5": {"fisher": "gauss_newton", "fisher_subsample": 5},
}
QUICK_VARIANTS = ("reference", "gauss_newton+subsample5")


def make_configs(env_name: str, variant: str) -> tuple[RolloutConfig, TRPOConfig]:
    """The rollout's shape for ``env_name`` and TRPO's settings of ``variant``."""
    sizes = {} if env_name == "Pendulum-v1" else {"num_envs": 16, "unroll_length": 64}
    return RolloutConfig(**sizes), TRPOConfig(**VARIANTS[variant])


def initial_states(env_name: str, env, num_seeds: int, key: jax.Array):
    """TRPOState with a leading seed axis; the Fisher options do not change its shapes."""
    rollout, trpo_config = make_configs(env_name, "reference")
    trpo = TRPO(rollout, env, trpo_config)
    return jax.jit(jax.vmap(trpo.init))(jax.random.split(key, num_seeds))


def measure_training(configs, env, states, num_iterations: int, mesh=None) -> dict:
    """Compiles and times ``num_iterations`` rollout+update iterations of every seed in states
    (``configs``: the rollout's and TRPO's, as ``make_configs`` gives them)."""
    config, trpo_config = configs
    trpo = TRPO(config, env, trpo_config)
    hyperparams = TRPOHyperparams.create()
    num_seeds = jax.tree.leaves(states)[0].shape[0]

    def run(hyperparams, state):
        def iteration(state, _):
            state, transitions = trpo.rollout(state)
            state, metrics = trpo.update(hyperparams, state, transitions, transitions.reward)
            return state, metrics["train/reward"]

        return jax.lax.scan(iteration, state, None, length=num_iterations)

    if mesh is not None:
        seeds_axis = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("seeds"))
        states = jax.device_put(states, seeds_axis)
    start = time.perf_counter()
    compiled = jax.jit(jax.vmap(run, in_axes=(None, 0))).lower(hyperparams, states).compile()
    compile_seconds = time.perf_counter() - start
    timings = []
    for _ in range(NUM_REPEATS):
        start = time.perf_counter()
        states, rewards = compiled(hyperparams, states)
        jax.block_until_ready((states, rewards))
        timings.append(time.perf_counter() - start)
    peak = peak_memory_bytes(compiled)
    steps = num_iterations * config.batch_size * num_seeds
    return {
        "steps_per_second": steps / statistics.median(timings),
        "compile_seconds": compile_seconds,
        "peak_memory_bytes": peak,
        "finite": bool(np.isfinite(np.asarray(rewards)).all()),
    }


def sharding_measurements(num_devices: int, num_iterations: int) -> dict:
    """Pendulum-v1, reference fidelity, 5N seeds: on one device, then sharded over N."""
    if jax.device_count() < num_devices:
        raise RuntimeError(f"needs {num_devices} devices, jax sees {jax.devices()}")
    env, config = envs.make("Pendulum-v1"), make_configs("Pendulum-v1", "reference")
    states = initial_states("Pendulum-v1", env, 5 * num_devices, jax.random.key(0))
    result = {"one_device": measure_training(config, env, states, num_iterations)}
    if num_devices > 1:
        mesh = jax.make_mesh((num_devices,), ("seeds",), axis_types=(jax.sharding.AxisType.Auto,))
        result["sharded"] = measure_training(config, env, states, num_iterations, mesh=mesh)
    return result


def sharding_rows(num_devices: int, num_iterations: int, common: dict) -> list[dict]:
    """One device here, then one device and N sharded in a subprocess that sees N devices.

    XLA reads ``--xla_force_host_platform_device_count`` when its backend starts, which in this
    process has already happened.
    """
    plain = sharding_measurements(1, num_iterations)["one_device"]
    flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count="
    environment = dict(os.environ, XLA_FLAGS=f"{flags}{num_devices}".strip())
    command = [sys.executable, __file__, "--sharding-worker", str(num_devices)]
    command += ["--iterations", str(num_iterations)]
    process = subprocess.run(command, env=environment, capture_output=True, text=True)
    try:
        result = json.loads(process.stdout.strip().splitlines()[-1])
    except (IndexError, json.JSONDecodeError):
        result = {"error": process.stderr[-2000:]}
    if "error" in result:
        print(f"sharding failed (exit {process.returncode}): {result['error']}", flush=True)
    settings = [("1 device, plain process", 1, plain)]
    if "sharded" in result:
        settings.append((f"1 device of {num_devices} exposed", 1, result["one_device"]))
        settings.append((f"sharded over {num_devices} devices", num_devices, result["sharded"]))
    print(
        f"\nPendulum-v1, reference fidelity, {5 * num_devices} seeds, {num_iterations} iterations"
    )
    print("\n| setting | train steps/s | compile s | vs plain |\n|---|---:|---:|---:|")
    rows = []
    for label, devices, measured in settings:
        ratio = measured["steps_per_second"] / plain["steps_per_second"]
        speed, seconds = measured["steps_per_second"], measured["compile_seconds"]
        print(f"| {label} | {speed:,.0f} | {seconds:.1f} | {ratio:.2f} |", flush=True)
        name = "reference/sharded" if devices > 1 else "reference"
        extra = {"setting": label, "devices": devices, "ratio_vs_plain": ratio}
        rows.append(make_row(name, "Pendulum-v1", 25, 5 * num_devices, measured, common, extra))
    if "sharded" in result:
        ratio = result["sharded"]["steps_per_second"] / result["one_device"]["steps_per_second"]
        print(f"\nsharded / unsharded in the same {num_devices}-device process: {ratio:.2f}")
    return rows


def make_row(variant, env_name, num_envs, num_seeds, measured, common, extra) -> dict:
    """A row in env_throughput's schema (width = all parallel envs) plus ``extra``."""
    width = num_envs * num_seeds
    row = {"name": f"trpo_train/{variant}", "env": env_name, "width": width, **measured}
    return {**row, **common, "seeds": num_seeds, "num_envs": num_envs, **extra}


def training_rows(names, seed_counts, brax_seed_counts, variants, num_iterations, common):
    key, rows = jax.random.key(0), []
    for name in names:
        env = envs.make(name)
        for num_seeds in seed_counts if name == "Pendulum-v1" else brax_seed_counts:
            width = make_configs(name, "reference")[0].num_envs * num_seeds
            key, env_key, init_key = jax.random.split(key, 3)
            env_speed = env_ceiling(env, width, scan_length(name, width, False), env_key)
            env_speed = env_speed["steps_per_second"]
            print(f"{name} width {width}: env only {env_speed:,.0f} steps/s", flush=True)
            states = initial_states(name, env, num_seeds, init_key)
            for variant in variants:
                config, trpo_config = make_configs(name, variant)
                result = measure_training((config, trpo_config), env, states, num_iterations)
                speed = result["steps_per_second"]
                extra = {
                    "unroll_length": config.unroll_length,
                    "fisher": trpo_config.fisher,
                    "fisher_subsample": trpo_config.fisher_subsample,
                    "env_steps_per_second": env_speed,
                    "train_over_env_ratio": speed / env_speed,
                    "speedup_vs_reference": speed / REFERENCE_SPEED,
                }
                rows.append(
                    make_row(variant, name, config.num_envs, num_seeds, result, common, extra)
                )
                warning = "" if result["finite"] else "  WARNING: non-finite rewards"
                print(
                    f"  {variant:24s} seeds={num_seeds:3d} {speed:>10,.0f} steps/s  "
                    f"compile {result['compile_seconds']:5.1f} s{warning}",
                    flush=True,
                )
    return rows


def rows_table(rows: list[dict]) -> str:
    header = [
        "env", "fisher", "subsample", "seeds", "width", "compile s", "train steps/s",
        "env-only steps/s", "train/env", "peak MiB", "vs 4,400",
    ]  # fmt: skip
    cells = [
        [row["env"], row["fisher"], row["fisher_subsample"], row["seeds"], row["width"],
         f"{row['compile_seconds']:.1f}", f"{row['steps_per_second']:,.0f}",
         f"{row['env_steps_per_second']:,.0f}", f"{row['train_over_env_ratio']:.3f}",
         mebibytes(row["peak_memory_bytes"]), f"{row['speedup_vs_reference']:.1f}x"]
        for row in rows
    ]  # fmt: skip
    return markdown_table(header, cells, "llrrrrrrrrr")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", default="Pendulum-v1,Hopper", help="comma-separated names")
    parser.add_argument("--seeds", default="1,5,35", help="comma-separated seed counts")
    parser.add_argument("--brax-seeds", default=None, help="seed counts for Brax (default --seeds)")
    parser.add_argument("--iterations", type=int, default=3, help="timed iterations per call")
    parser.add_argument("--quick", action="store_true", help="Pendulum, seeds 1,5, two rows")
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    parser.add_argument("--devices", type=int, default=None, help="only the sharding study")
    parser.add_argument("--sharding-worker", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.sharding_worker:
        try:
            result = sharding_measurements(args.sharding_worker, args.iterations)
        except Exception as error:  # the parent reports it instead of a traceback
            result = {"error": f"{type(error).__name__}: {error}"}
        print(json.dumps(result))
        return

    names = ["Pendulum-v1"] if args.quick else [n.strip() for n in args.envs.split(",") if n]
    seed_counts = (1, 5) if args.quick else tuple(int(s) for s in args.seeds.split(","))
    brax_seed_counts = tuple(int(s) for s in (args.brax_seeds or args.seeds).split(","))
    variants = QUICK_VARIANTS if args.quick else tuple(VARIANTS)
    common = context()
    print(f"device {common['device']}, jax {jax.__version__}", flush=True)
    if args.devices:
        rows = sharding_rows(args.devices, args.iterations, common)
    else:
        rows = training_rows(
            names, seed_counts, brax_seed_counts, variants, args.iterations, common
        )
        sizes = [(name, make_configs(name, "reference")[0]) for name in names]
        sizes = "; ".join(f"{n}: {c.num_envs} envs x {c.unroll_length} steps" for n, c in sizes)
        print(f"\n{sizes}; {args.iterations} iterations per call; speed-up {REFERENCE_NOTE}.\n")
        print(rows_table(rows), flush=True)
    write_rows(args.json, rows)


if __name__ == "__main__":
    main()
