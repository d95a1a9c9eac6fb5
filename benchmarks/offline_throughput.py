"""The offline family's cost: one grid of every method against each method in a grid of its
own, side by side in one run.

A vmapped grid computes every compiled part in every cell (a BC cell also pays for DWBC's and
ISW-BC's discriminators), so one mixed program does more arithmetic than the methods' own
programs together, and compiles once instead of once per method. This measures both:
gradient steps per second per cell, each program's compile time, and the mixed grid's time
over the sum of the separate ones.

    python benchmarks/offline_throughput.py --json offline.json   # a few minutes on 2 cores
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax
from common import context, markdown_table, time_grid_chunks, write_rows

from pngail_jax import envs
from pngail_jax.demos import load_released
from pngail_jax.grid import Grid, make_cells, stack_cells
from pngail_jax.offline.family import OFFLINE
from pngail_jax.offline.trainer import (
    OFFLINE_METHOD_NAMES,
    OfflineConfig,
    OfflineTrainer,
)

DEFAULT_DEMOS = Path(__file__).resolve().parents[1] / "data/released/Pendulum-v1_mixture.npy"


def measure(env, demos, methods, args) -> dict:
    config = OfflineConfig(
        num_iterations=args.iterations * 2,
        steps_per_iteration=args.steps,
        eval_every=args.iterations,
        batch_size=args.batch_size,
        components=OFFLINE.parts(methods),
    )
    trainer = OfflineTrainer(config, env, demos)
    cells = make_cells(methods, args.seeds)
    grid = Grid(trainer, stack_cells(cells, jax.random.key(0), family=OFFLINE), blocks_per_chunk=1)
    _, _, _, chunk_seconds = time_grid_chunks(grid, repeats=1)
    steps = args.iterations * args.steps
    return {
        "name": "offline",
        "methods": ",".join(methods),
        "cells": len(cells),
        "compile_seconds": grid.compile_seconds,
        "chunk_seconds": chunk_seconds,
        "steps_per_second_per_cell": steps / chunk_seconds,
        **context(),
    }


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--demos", type=Path, default=DEFAULT_DEMOS)
    parser.add_argument("--methods", default=",".join(OFFLINE_METHOD_NAMES))
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=100, help="gradient steps per iteration")
    parser.add_argument("--iterations", type=int, default=5, help="iterations per timed chunk")
    parser.add_argument("--batch-size", type=int, default=256)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    if not args.demos.exists():
        parser.error(f"{args.demos} not found: pass --demos PATH/Pendulum-v1_mixture.npy")
    demos = load_released(args.demos)
    env = envs.make(demos.metadata.get("env", "Pendulum-v1"))
    methods = [name.strip() for name in args.methods.split(",")]
    rows = [measure(env, demos, methods, args)]
    rows += [measure(env, demos, [name], args) for name in methods]
    separate = sum(row["chunk_seconds"] for row in rows[1:])
    rows[0]["over_separate_ratio"] = rows[0]["chunk_seconds"] / separate
    for row in rows:
        print(
            f"{row['methods']:>28}: {row['cells']} cells, {row['steps_per_second_per_cell']:7.1f}"
            f" steps/s per cell, compile {row['compile_seconds']:.1f} s",
            flush=True,
        )
    header = ["grid", "cells", "gradient steps/s per cell", "chunk s", "compile s"]
    cells = [
        [r["methods"], r["cells"], f"{r['steps_per_second_per_cell']:.1f}",
         f"{r['chunk_seconds']:.2f}", f"{r['compile_seconds']:.1f}"]
        for r in rows
    ]  # fmt: skip
    print("\n" + markdown_table(header, cells, "lrrrr"))
    print(
        f"\nthe mixed grid's chunk / the separate grids' chunks together: "
        f"{rows[0]['over_separate_ratio']:.2f}"
    )
    write_rows(args.json, rows)
    return rows


if __name__ == "__main__":
    main()
