"""Environment-only throughput: the ceiling every training throughput is compared against.

For each environment and parallel width, compiles ``lax.scan`` over ``jit(vmap(env.step))``
fed with pre-drawn uniform random actions, then times warm calls (median of 3). Reports
steps/s (environment transitions, all slots counted), compile seconds (tracing + XLA) and peak
memory (XLA's ``memory_analysis()`` of the compiled program: arguments + outputs + temporaries,
the device buffers it needs; process RSS is dominated by the JAX runtime and not per config).

    python benchmarks/env_throughput.py --quick            # about 3 minutes on a 2-core CPU
    python benchmarks/env_throughput.py --json out.json    # all widths, both solver settings

Writes ``env_throughput.{json,md,png}`` to ``--out`` (default ``results/env_throughput``); with
``--json PATH`` the rows also go to PATH. Row schema: ``{name, env, width, steps_per_second,
compile_seconds, peak_memory_bytes, device, jax_version}`` plus ``solver``, ``num_steps`` and
``diverged_fraction`` (slots whose rewards went non-finite under random actions: the fast MJX
solver makes HalfCheetah diverge now and then).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import jax
from common import context, env_ceiling, markdown_table, mebibytes, scan_length, write_rows

from pngail_jax import envs

CPU_WIDTHS = (1, 4, 16, 64, 256)
GPU_WIDTHS = (1, 64, 512, 2048, 8192)
QUICK_PENDULUM_WIDTHS = (1, 16, 256)
QUICK_MUJOCO_WIDTHS = (16,)


def configurations(env_names, quick: bool, on_gpu: bool, fast_solver_only: bool, physics=None):
    """Yields (env_name, solver_label, make_options, widths); ``physics``: the engines of
    gymnasium's tasks to measure (default: every one installed)."""
    for name in env_names:
        if name == "Pendulum-v1":
            widths = QUICK_PENDULUM_WIDTHS if quick else (GPU_WIDTHS if on_gpu else CPU_WIDTHS)
            yield name, "-", {}, widths
            continue
        widths = QUICK_MUJOCO_WIDTHS if quick else (GPU_WIDTHS if on_gpu else CPU_WIDTHS)
        if name in envs.GYM_TASKS:
            # gymnasium's tasks keep gymnasium's solver; one row per engine.
            for engine in physics or envs.available_physics():
                yield name, f"gymnasium's, physics {engine}", {"physics": engine}, widths
            continue
        if name == "Ant":
            # Brax's own Ant already runs the fast setting (Newton, 1 / 4 iterations).
            yield name, "default=fast", {}, widths
            continue
        if not (quick or fast_solver_only):
            yield name, "default", {}, widths
        yield name, "fast", envs.FAST_SOLVER, widths


def rows_table(rows: list[dict]) -> str:
    header = ["env", "solver", "width", "steps/s", "compile s", "peak memory MiB", "diverged"]
    cells = [
        [row["env"], row["solver"], row["width"], f"{row['steps_per_second']:,.0f}",
         f"{row['compile_seconds']:.1f}", mebibytes(row["peak_memory_bytes"]),
         f"{row['diverged_fraction']:.0%}"]
        for row in rows
    ]  # fmt: skip
    return markdown_table(header, cells, "llrrrrr")


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    title = f"Environment-only throughput ({rows[0]['device']}, jax {rows[0]['jax_version']})"
    series = {}
    for row in rows:
        label = row["env"] if row["solver"] == "-" else f"{row['env']} ({row['solver']} solver)"
        series.setdefault(label, []).append((row["width"], row["steps_per_second"]))
    if all(len(points) == 1 for label, points in series.items() if "solver" in label):
        # Quick mode: one width per MuJoCo task, which reads better as bars than as dots.
        figure, axis = plt.subplots(figsize=(9, 4.5))
        labels = [
            f"{row['env']} ({row['solver']}) x{row['width']}"
            if row["solver"] != "-"
            else f"{row['env']} x{row['width']}"
            for row in rows
        ]
        axis.barh(labels, [row["steps_per_second"] for row in rows], color="tab:blue")
        axis.invert_yaxis()
        axis.set(
            xscale="log", xlabel="environment steps / s (log scale)", title=title, xlim=(1e3, None)
        )
        axis.grid(True, axis="x", which="both", alpha=0.3)
    else:
        figure, axis = plt.subplots(figsize=(9, 4.5))
        for label, points in series.items():
            widths, speeds = zip(*sorted(points), strict=True)
            axis.plot(widths, speeds, marker="o", label=label)
        axis.set(
            xscale="log",
            yscale="log",
            xlabel="parallel environments (vmap width)",
            ylabel="environment steps / s",
            title=title,
        )
        axis.grid(True, which="both", alpha=0.3)
        axis.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def _physics(parser, text: str | None) -> list[str] | None:
    """The engines ``--physics`` lists (None: every one installed), or a parser error."""
    if not text:
        return None
    physics = [engine.strip() for engine in text.split(",") if engine.strip()]
    if not physics or set(physics) - set(envs.available_physics()):
        parser.error(
            f"--physics: comma-separated engines among {', '.join(envs.available_physics())}"
            f" (installed), got {text!r}"
        )
    return physics


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--envs",
        default=",".join(envs.ENV_NAMES),
        help="comma-separated environment names (default: all)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="few widths and the fast MJX solver only (a few minutes on a CPU)",
    )
    parser.add_argument(
        "--fast-solver-only",
        action="store_true",
        help="skip the default-solver rows of the MuJoCo tasks",
    )
    parser.add_argument(
        "--widths",
        default=None,
        help="comma-separated widths overriding the defaults for every env",
    )
    parser.add_argument(
        "--physics",
        default=None,
        help="comma-separated engines of gymnasium's tasks (default: every one installed: "
        f"{', '.join(envs.available_physics())})",
    )
    parser.add_argument("--out", type=Path, default=Path("results/env_throughput"))
    parser.add_argument("--json", type=Path, default=None, help="also write the rows here")
    parser.add_argument("--seed", type=int, default=0)
    return parser


def main(argv=None) -> None:
    parser = _parser()
    args = parser.parse_args(argv)

    names = [name.strip() for name in args.envs.split(",") if name.strip()]
    unknown = sorted(set(names) - set(envs.ENV_NAMES))
    if unknown:
        parser.error(f"unknown environment(s) {unknown}; available: {', '.join(envs.ENV_NAMES)}")
    widths_override = None
    if args.widths:
        widths_override = tuple(int(w) for w in args.widths.split(","))
        if min(widths_override) < 1:
            parser.error("--widths must be positive integers")
    on_gpu = jax.devices()[0].platform == "gpu"
    key = jax.random.key(args.seed)
    rows = []
    print(f"device {context()['device']}, jax {jax.__version__}", flush=True)
    physics = _physics(parser, args.physics)
    for name, solver, options, widths in configurations(
        names, args.quick, on_gpu, args.fast_solver_only, physics
    ):
        if options.get("physics") == "warp":  # Warp's contact buffer: the widest batch
            options = {**options, "warp_batch": max(widths_override or widths)}
        env = envs.make(name, **options)
        for width in widths_override or widths:
            key, measure_key = jax.random.split(key)
            num_steps = scan_length(name, width, args.quick)
            result = env_ceiling(env, width, num_steps, measure_key)
            row = {
                "name": "env_step",
                "env": name,
                "solver": solver,
                "width": width,
                "num_steps": num_steps,
                **result,
                **context(),
            }
            rows.append(row)
            warning = ""
            if result["diverged_fraction"]:
                warning = f"  WARNING: {result['diverged_fraction']:.0%} of slots went non-finite"
            print(
                f"  {name:12s} solver={solver:12s} width={width:5d}  "
                f"{row['steps_per_second']:>12,.0f} steps/s  "
                f"compile {row['compile_seconds']:5.1f} s{warning}",
                flush=True,
            )

    table = rows_table(rows)
    print("\n" + table)
    args.out.mkdir(parents=True, exist_ok=True)
    write_rows(args.out / "env_throughput.json", rows)
    (args.out / "env_throughput.md").write_text(table + "\n")
    plot(rows, args.out / "env_throughput.png")
    write_rows(args.json, rows)
    print(f"\nwrote {args.out}/env_throughput.{{json,md,png}}", file=sys.stderr)


if __name__ == "__main__":
    main()
