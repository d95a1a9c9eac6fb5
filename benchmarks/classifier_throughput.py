"""The confidence-classifier phase: time, accuracy and BSC's clip across batch sizes.

For each labelled batch size (1 is the reference's 1 labelled + 4 unlabelled rows per step),
compiles and runs SC and BSC on ``--seeds`` seeds in one vmapped program on the authors'
Pendulum set (label ratio 0.2), and reports compile and run seconds, the time per classifier
run, MAE / RMSE on the unlabelled rows and the fraction of steps where BSC's clip was active
(when it is, the balance term passes no gradient). Also times a single run, for the ratio of
one program of N runs over N single runs.

    python benchmarks/classifier_throughput.py --json classifier.json   # ~2 min on 2 cores

The reference PyTorch classifier takes about 18 s for one 25,000-step run on one core of
this machine type (measured by the project, not in this run).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax
import jax.numpy as jnp
from common import compile_and_run, context, markdown_table, write_rows

from pngail_jax.confidence import ClassifierConfig, ClassifierSpec, split_and_train
from pngail_jax.demos import load_released

# The authors' Pendulum set, downloaded into data/released/ (docs/demonstrations.md).
DEFAULT_DEMOS = Path(__file__).resolve().parents[1] / "data/released/Pendulum-v1_mixture.npy"


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--demos", type=Path, default=DEFAULT_DEMOS)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=25_000)
    parser.add_argument("--batch-sizes", default="1,4,16")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    if not args.demos.exists():
        parser.error(f"{args.demos} not found: pass --demos PATH/Pendulum-v1_mixture.npy")
    demos = load_released(args.demos)
    inputs, confidence = jnp.asarray(demos.inputs), jnp.asarray(demos.confidence)
    specs = [("sc", ClassifierSpec.sc()), ("bsc", ClassifierSpec.bsc())]
    stacked = jax.tree.map(
        lambda *x: jnp.repeat(jnp.stack(x), args.seeds, axis=0), *(spec for _, spec in specs)
    )
    keys = jnp.tile(jax.random.split(jax.random.key(0), args.seeds), len(specs))
    rows = []
    for batch_size in (int(b) for b in args.batch_sizes.split(",")):
        config = ClassifierConfig(
            num_steps=args.steps,
            labelled_batch_size=batch_size,
            unlabelled_batch_size=4 * batch_size,
        )

        def run(spec, key, config=config):
            return split_and_train(config, spec, inputs, confidence, demos.num_rows, 0.2, 0.0, key)

        results, compile_seconds, run_seconds = compile_and_run(jax.vmap(run), stacked, keys)
        _, single_compile, single_run = compile_and_run(run, ClassifierSpec.bsc(), keys[0])
        num_runs = len(specs) * args.seeds
        row = {
            "name": "classifier",
            "batch": f"{batch_size}+{4 * batch_size}",
            "runs": num_runs,
            "steps": args.steps,
            "compile_seconds": compile_seconds,
            "run_seconds": run_seconds,
            "seconds_per_run": run_seconds / num_runs,
            "single_run_seconds": single_run,
            "grid_over_single_ratio": run_seconds / (num_runs * single_run),
            **context(),
        }
        for index, (name, _) in enumerate(specs):
            part = slice(index * args.seeds, (index + 1) * args.seeds)
            row[f"{name}_mae"] = float(results["mae"][part].mean())
            row[f"{name}_rmse"] = float(results["rmse"][part].mean())
        row["bsc_clip_active"] = float(results["clip_active"][args.seeds :].mean())
        rows.append(row)
        print(
            f"batch {row['batch']:>6}: {num_runs} runs in {run_seconds:5.1f} s "
            f"(+{compile_seconds:.1f} s compile), single run {single_run:.1f} s; "
            f"BSC MAE {row['bsc_mae']:.3f}, SC MAE {row['sc_mae']:.3f}, "
            f"clip active {row['bsc_clip_active']:.0%}",
            flush=True,
        )

    header = [
        "labelled+unlabelled per step", "runs", "run s", "s per run", "1 run alone s",
        "grid / N singles", "SC MAE", "BSC MAE", "BSC RMSE", "BSC clip active",
    ]  # fmt: skip
    cells = [
        [r["batch"], r["runs"], f"{r['run_seconds']:.1f}", f"{r['seconds_per_run']:.2f}",
         f"{r['single_run_seconds']:.1f}", f"{r['grid_over_single_ratio']:.2f}",
         f"{r['sc_mae']:.3f}", f"{r['bsc_mae']:.3f}", f"{r['bsc_rmse']:.3f}",
         f"{r['bsc_clip_active']:.0%}"]
        for r in rows
    ]  # fmt: skip
    print("\n" + markdown_table(header, cells, "lrrrrrrrrr"))
    write_rows(args.json, rows)
    return rows


if __name__ == "__main__":
    main()
