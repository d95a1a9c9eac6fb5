"""What each method costs: its set-up (classifier, reward fits, cloning) and one training
iteration, side by side on one machine and one task, at the settings a run uses.

For each method of ``--methods`` the script builds the run the sweep would build
(``RunConfig(methods=(method,), seeds=--seeds)``, the task's run settings, the appendix
phases at their codebases' settings: ``pngail_jax.jobs.build.build_run``), then times, warm:

- ``init_seconds``: the grid's ``init`` (the split, the SC/BSC classifier, and the method's
  training phases: T-REX's and D-REX's reward fits, D-REX's cloning and noisy rollouts, BC),
  one call after the compile;
- ``iteration_seconds``: one chunk of ``--iterations`` iterations (rollout, the method's
  discriminator or reward steps, the TRPO update; an evaluation at its end), median of
  ``--repeats`` calls, divided by the iterations;
- ``ratio_to_first``: ``iteration_seconds`` over the first method's, measured in the same
  process one after the other (the machine's load hits them alike only roughly; rerun on a
  shared machine).

Seconds are per call for all ``--seeds`` cells of the method (one compiled program, as in a
grid). The demonstrations are ``--demos`` (default: the authors' Pendulum file in
``data/released/``, else made by the run on first use, which takes minutes).

    python benchmarks/method_cost.py --methods pngail,firl-fkl --quick
    python benchmarks/method_cost.py --json rows.json    # pngail, gail, cail, trex, firl-fkl

Row schema: ``{name, env, method, seeds, iterations, init_seconds, iteration_seconds,
ratio_to_first, compile_seconds, device, jax_version}``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from common import context, markdown_table, time_grid_chunks, write_rows

from pngail_jax import RunConfig
from pngail_jax.jobs.build import build_run
from pngail_jax.jobs.errors import RunError

DEFAULT_METHODS = ("pngail", "gail", "cail", "trex", "firl-fkl")
RELEASED_PENDULUM = Path("data/released/Pendulum-v1_mixture.npy")


def measure(config: RunConfig, repeats: int) -> dict:
    """Compiles ``config``'s grid and times its init and one chunk (see the module doc)."""
    grid = build_run(config).grid
    _, _, init_seconds, chunk_seconds = time_grid_chunks(grid, repeats)
    return {
        "init_seconds": init_seconds,
        "iteration_seconds": chunk_seconds / config.iterations,
        "compile_seconds": grid.compile_seconds,
    }


def method_config(args, method: str) -> RunConfig:
    """A one-method run of ``args.seeds`` seeds whose one chunk is ``args.iterations``
    iterations with one evaluation at its end."""
    shape = {"num_envs": args.num_envs, "unroll_length": args.unroll_length}
    settings = RunConfig.preset("smoke").settings.replace(
        eval_every=args.iterations, **{k: v for k, v in shape.items() if v is not None}
    )
    return RunConfig(
        env=args.env,
        methods=(method,),
        seeds=args.seeds,
        iterations=args.iterations,
        chunk_iterations=args.iterations,
        demos=args.demos,
        settings=settings,
    )


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter
    )
    parser.add_argument("--env", default="Pendulum-v1")
    parser.add_argument(
        "--methods", default=",".join(DEFAULT_METHODS), help="comma-separated method names"
    )
    parser.add_argument("--seeds", type=int, default=1, help="cells per method")
    parser.add_argument("--iterations", type=int, default=4, help="iterations per timed chunk")
    parser.add_argument("--repeats", type=int, default=3, help="timed chunks per method")
    parser.add_argument("--demos", default=None, help="demonstrations (default: see above)")
    parser.add_argument("--num-envs", type=int, default=None, help="default: the task's")
    parser.add_argument("--unroll-length", type=int, default=None, help="default: the task's")
    parser.add_argument("--quick", action="store_true", help="2 iterations, 1 timed chunk")
    parser.add_argument("--json", default=None, help="write the rows here")
    args = parser.parse_args(argv)
    if args.quick:
        args.iterations, args.repeats = 2, 1
    if min(args.seeds, args.iterations, args.repeats) < 1:
        parser.error("--seeds, --iterations and --repeats must be at least 1")
    if args.demos is None and args.env == "Pendulum-v1" and RELEASED_PENDULUM.exists():
        args.demos = str(RELEASED_PENDULUM)
    args.methods = tuple(name.strip() for name in args.methods.split(",") if name.strip())
    return args


def main(argv=None) -> list[dict]:
    args = parse_args(argv)
    rows = []
    for method in args.methods:
        try:
            config = method_config(args, method)
        except ValueError as error:
            sys.exit(f"--methods: {error}")
        print(f"{method}: building and timing ...", flush=True)
        try:
            result = measure(config, args.repeats)
        except RunError as error:
            sys.exit(str(error))
        rows.append(
            {
                "name": f"method_cost/{method}",
                "env": args.env,
                "method": method,
                "seeds": args.seeds,
                "iterations": args.iterations,
                **result,
                **context(),
            }
        )
    for row in rows:
        row["ratio_to_first"] = row["iteration_seconds"] / rows[0]["iteration_seconds"]
    print()
    print(
        markdown_table(
            ["method", "set-up s", "s / iteration", f"x {rows[0]['method']}", "compile s"],
            [
                [
                    row["method"],
                    f"{row['init_seconds']:.1f}",
                    f"{row['iteration_seconds']:.3f}",
                    f"{row['ratio_to_first']:.1f}",
                    f"{row['compile_seconds']:.1f}",
                ]
                for row in rows
            ],
            "lrrrr",
        )
    )
    print(
        f"\n{args.env}, {args.seeds} seed(s) per method in one program, {rows[0]['device']}; "
        "seconds per call for all seeds"
    )
    write_rows(args.json, rows)
    return rows


if __name__ == "__main__":
    main()
