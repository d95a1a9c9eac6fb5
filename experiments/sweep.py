"""The main job: every method x seed (x label ratio x noise) as one compiled program.

    python -m experiments.sweep        # smoke scale: Pendulum-v1, 7 methods x 3 seeds
    python -m experiments.sweep --demos data/pendulum/Pendulum-v1_mixture.npy \\
        --action-scale 2 --seeds 5 --iterations 1000
    python -m experiments.sweep --preset paper --demos ...   # 5,000 iterations, 5 seeds (GPU)
    python -m experiments.sweep --resume runs/20261122-210000

Without ``--demos`` the demonstrations are made by ``experiments.make_demos`` (1:4 optimal to
intermediate trajectories) once and reused from ``runs/demos-cache/<env>/``. Writes to
``--out`` (default ``runs/<timestamp>``): ``config.json``, ``metrics.csv``, ``curves.png``,
``summary.md``, ``summary.json`` and ``checkpoints/`` (the whole grid's state after every chunk;
``--resume DIR`` continues from the last one to the numbers of an uninterrupted run).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from experiments.cli import known_names
from pngail_jax import compilation
from pngail_jax import settings as run_settings

DEFAULTS = {  # the smoke scale: a few minutes on a 2-core CPU
    "iterations": 300,
    "seeds": 3,
    "chunk_iterations": 50,
    "classifier_steps": 25_000,
}
RUN_PRESETS = {
    "paper": {"iterations": 5_000, "seeds": 5, "chunk_iterations": 250},
}
DEMO_CACHE = Path("runs") / "demos-cache"


def parse_args(argv=None) -> argparse.Namespace:
    from pngail_jax import envs
    from pngail_jax.methods import METHOD_NAMES, PRESETS

    methods_help = "\n".join(
        f"  {name:14s} {preset.description} (r: {preset.confidence_source})"
        for name, preset in PRESETS.items()
    )
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog=f"methods:\n{methods_help}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--env", default="Pendulum-v1", help=f"one of {', '.join(envs.ENV_NAMES)}")
    parser.add_argument(
        "--methods",
        default=",".join(METHOD_NAMES),
        help=f"comma-separated, from {', '.join(METHOD_NAMES)} (default: all)",
    )
    parser.add_argument("--seeds", type=int, help=f"default {DEFAULTS['seeds']}")
    parser.add_argument("--iterations", type=int, help=f"default {DEFAULTS['iterations']}")
    parser.add_argument(
        "--preset", choices=sorted(RUN_PRESETS), help="paper: 5,000 iterations, 5 seeds"
    )
    parser.add_argument("--demos", type=Path, help="*_mixture.npy (authors' layout) or *.npz")
    parser.add_argument("--conf", type=Path, help="confidence file (default: the sibling)")
    parser.add_argument(
        "--action-scale",
        type=float,
        default=1.0,
        help="multiplies stored actions (2 for the authors' Pendulum set)",
    )
    parser.add_argument(
        "--num-demos", type=int, help="rows per split, n_c + n_u (default: all rows)"
    )
    parser.add_argument("--label-ratio", default="0.2", help="comma-separated values: a grid axis")
    parser.add_argument("--noise", default="0", help="confidence noise std, comma-separated")
    parser.add_argument("--seed", type=int, default=0, help="base PRNG seed")
    parser.add_argument(
        "--chunk-iterations",
        type=int,
        help=f"iterations per compiled chunk (progress + checkpoint); default "
        f"{DEFAULTS['chunk_iterations']}",
    )
    parser.add_argument("--classifier-steps", type=int, help="default 25,000 (the paper's)")
    parser.add_argument(
        "--fisher",
        choices=("hessian", "gauss_newton"),
        default="gauss_newton",
        help="Fisher-vector product: the same matrix either way (the Hessian of the mean KL at "
        "the current policy); gauss_newton is 1.7x faster here, hessian the reference's form",
    )
    parser.add_argument("--fisher-subsample", type=int, default=1)
    parser.add_argument(
        "--cpu-devices",
        type=int,
        help="on a CPU, split it into this many XLA devices and shard the grid over them "
        "(default 1: on 2 cores one device already uses both, and 2 measured no faster)",
    )
    parser.add_argument("--out", type=Path, help="output directory (default runs/<timestamp>)")
    run_settings.add_arguments(parser)
    compilation.add_arguments(parser)
    multihost = parser.add_argument_group(
        "multi-host (run the same command on every host; process 0 writes the outputs)"
    )
    multihost.add_argument("--coordinator", help="host:port of process 0, for jax.distributed")
    multihost.add_argument("--num-processes", type=int)
    multihost.add_argument("--process-id", type=int)
    parser.add_argument("--resume", type=Path, metavar="DIR", help="continue DIR's run")
    parser.set_defaults(run_settings=None)
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    distributed = (args.coordinator, args.num_processes, args.process_id)
    if any(x is not None for x in distributed) and any(x is None for x in distributed):
        parser.error("--coordinator, --num-processes and --process-id go together")
    if args.resume is not None:
        allowed = (
            "--resume",
            "--coordinator",
            "--num-processes",
            "--process-id",
            "--compile-cache",
            "--no-compile-cache",
        )
        flags = [a.split("=")[0] for a in argv if a.startswith("--")]
        if any(flag not in allowed for flag in flags):
            parser.error(
                "--resume DIR takes no other flags (except the multi-host ones): the run's "
                "config.json has them"
            )
        return args
    if args.coordinator is not None and args.demos is None:
        parser.error("multi-host runs need --demos (a file every host can read)")
    return resolve(parser, args)


def resolve(parser, args: argparse.Namespace) -> argparse.Namespace:
    """Fills defaults (preset, then smoke scale) and checks every value, naming the flag."""
    from pngail_jax import envs
    from pngail_jax.methods import METHOD_NAMES

    preset = RUN_PRESETS.get(args.preset, {})
    for name, value in DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, preset.get(name, value))
    if args.env not in envs.ENV_NAMES:
        parser.error(f"unknown environment {args.env!r}; available: {', '.join(envs.ENV_NAMES)}")
    args.methods = known_names(parser, args.methods, METHOD_NAMES, "method")
    positive = ("seeds", "iterations", "chunk_iterations", "classifier_steps")
    for name in (*positive, "fisher_subsample"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be positive")
    try:
        args.run_settings = run_settings.from_arguments(args.env, args)
    except ValueError as error:
        parser.error(str(error))
    args.eval_every = args.run_settings.eval_every
    if args.iterations % args.eval_every:
        parser.error(
            f"--iterations ({args.iterations}) must be a multiple of the evaluation interval "
            f"({args.eval_every}; set it with --eval-every)"
        )
    args.label_ratios = _floats(parser, "--label-ratio", args.label_ratio)
    args.noise_stds = _floats(parser, "--noise", args.noise)
    if not all(0 < r < 1 for r in args.label_ratios):
        parser.error("--label-ratio values must lie in (0, 1)")
    if not all(s >= 0 for s in args.noise_stds):
        parser.error("--noise values must be >= 0")
    if args.demos is not None and not args.demos.exists():
        parser.error(f"--demos {args.demos} does not exist")
    if args.out is None:
        args.out = Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    if (args.out / "config.json").exists():
        parser.error(f"{args.out} already holds a run: --resume {args.out}, or another --out")
    return args


def _floats(parser, flag: str, text: str) -> list[float]:
    try:
        values = [float(x) for x in str(text).split(",")]
    except ValueError:
        parser.error(f"{flag} must be comma-separated numbers, got {text!r}")
    return values


def load_or_make_demos(args):
    from pngail_jax.demos import load_demonstrations

    if args.demos is not None:
        return load_demonstrations(args.demos, args.conf, args.action_scale), str(args.demos)
    cached = DEMO_CACHE / args.env / "demos.npz"
    if cached.exists():
        print(f"reusing demonstrations {cached}", flush=True)
    else:
        print(f"no --demos: making them with experiments.make_demos into {cached.parent}")
        from experiments import make_demos

        make_demos.main(["--env", args.env, "--out", str(cached.parent)])
    return load_demonstrations(cached), str(cached)


def run_config(args, demos, demos_path) -> dict:
    names = (
        "env methods seeds iterations preset action_scale num_demos label_ratios noise_stds "
        "seed eval_every chunk_iterations classifier_steps fisher fisher_subsample cpu_devices"
    ).split()
    config = {name: getattr(args, name) for name in names}
    config["settings"] = dataclasses.asdict(args.run_settings)
    config["demos"] = str(Path(demos_path).absolute())
    config["conf"] = None if args.conf is None else str(args.conf.absolute())
    config["normalizer"] = normalizer_of(demos)
    return config


def saved_settings(saved: dict):
    """The run settings of a saved config.json; runs from before the settings table used the
    reference setting with their own shape and evaluation interval."""
    from pngail_jax.settings import REFERENCE_SETTINGS, RunSettings

    if "settings" in saved:
        return RunSettings(**saved["settings"])
    return REFERENCE_SETTINGS.replace(
        num_envs=saved["num_envs"],
        unroll_length=saved["unroll_length"],
        eval_every=saved["eval_every"],
    )


def normalizer_of(demos):
    metadata = demos.metadata
    if "random_return" in metadata and "optimal_return" in metadata:
        return [float(metadata["random_return"]), float(metadata["optimal_return"])]
    return None


def blocks_per_chunk(num_evaluations: int, target_blocks: int) -> int:
    """The largest divisor of num_evaluations not above the target (so all chunks match)."""
    return max(
        d for d in range(1, min(target_blocks, num_evaluations) + 1) if not num_evaluations % d
    )


def format_seconds(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 60}m{seconds % 60:02d}s" if seconds >= 60 else f"{seconds}s"


def configure_devices(requested: int | None) -> None:
    """Splits the CPU into ``requested`` XLA devices (before JAX starts its backend).

    Not by default: benchmarks/grid_throughput.py measured a 35-cell grid on 2 cores at
    89.9k steps/s on one device and 90.9k on two (one XLA CPU device already uses every core).
    """
    import jax

    if requested is not None and requested > 1:
        jax.config.update("jax_num_cpu_devices", requested)


def main(argv=None) -> Path:
    args = parse_args(argv)
    resume_dir = args.resume
    distributed = {
        "coordinator_address": args.coordinator,
        "num_processes": args.num_processes,
        "process_id": args.process_id,
    }
    if resume_dir is not None:
        config_path = resume_dir / "config.json"
        if not config_path.exists():
            raise SystemExit(f"--resume {resume_dir}: no config.json there")
        saved = json.loads(config_path.read_text())
        args = argparse.Namespace(
            **{**saved, "out": resume_dir, "resume": resume_dir},
            compile_cache=args.compile_cache,
            no_compile_cache=args.no_compile_cache,
        )
        args.run_settings = saved_settings(saved)
        args.demos = Path(saved["demos"])
        args.conf = None if saved["conf"] is None else Path(saved["conf"])
        if args.cpu_devices is None and saved["platform"] == "cpu":
            args.cpu_devices = saved["local_device_count"]  # the same sharding as before
    configure_devices(args.cpu_devices)
    import jax

    compilation.from_arguments(args)

    if distributed["coordinator_address"] is not None:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        jax.distributed.initialize(**distributed)
        if jax.process_index() != 0:
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115  process 0 reports
    writer = jax.process_index() == 0

    from pngail_jax import report
    from pngail_jax.checkpoint import restore_tree
    from pngail_jax.confidence import ClassifierConfig
    from pngail_jax.grid import Grid, make_cells, nonfinite_cells, stack_cells
    from pngail_jax.train import AdversarialConfig, make_train

    settings = args.run_settings
    env = run_settings.make_env(args.env, settings)
    demos, demos_path = load_or_make_demos(args)
    demos.check_env(env)
    config = AdversarialConfig(
        trpo=settings.trpo_config(
            args.iterations, fisher=args.fisher, fisher_subsample=args.fisher_subsample
        ),
        classifier=ClassifierConfig(num_steps=args.classifier_steps),
        num_demos=args.num_demos,
    )
    train = make_train(config, env, demos)
    for ratio in args.label_ratios:
        num_labelled = round(ratio * train.num_demos)
        if not 0 < num_labelled < train.num_demos:
            raise SystemExit(
                f"--label-ratio {ratio} labels {num_labelled} of {train.num_demos} rows; "
                "need at least one labelled and one unlabelled row"
            )
    out: Path = args.out
    if writer:
        out.mkdir(parents=True, exist_ok=True)
    devices = jax.devices()
    run = run_config(args, demos, demos_path)
    run |= {
        "platform": devices[0].platform,
        "device_count": len(devices),
        "local_device_count": len(jax.local_devices()),
    }
    if resume_dir is not None and saved["device_count"] != len(devices):
        print(
            f"WARNING: resuming on {len(devices)} devices, the run began on "
            f"{saved['device_count']}: a different sharding can change the last bits, and "
            "the rest of the run with them"
        )
    normalizer = run["normalizer"]
    if resume_dir is None and writer:
        (out / "config.json").write_text(json.dumps(run, indent=2))
    cells = make_cells(args.methods, args.seeds, args.label_ratios, args.noise_stds)
    if args.env == "Walker2d":
        overrides = {"bsc_eps": 0.05}  # the paper's Walker2d setting (appendix C.2)
    else:
        overrides = {}
    hyperparams, specs, keys = stack_cells(cells, jax.random.key(args.seed), overrides)
    num_evaluations = args.iterations // args.eval_every
    chunk_blocks = blocks_per_chunk(
        num_evaluations, max(1, args.chunk_iterations // args.eval_every)
    )
    print(
        f"{len(cells)} runs ({', '.join(args.methods)} x {args.seeds} seeds x "
        f"{len(args.label_ratios) * len(args.noise_stds)} setting(s)) on {args.env}, "
        f"{args.iterations} iterations x {config.trpo.batch_size} steps, "
        f"{train.num_demos} demonstration rows; {len(devices)} {devices[0].platform} device(s); "
        f"-> {out}\n  {run_settings.describe(settings)}",
        flush=True,
    )
    if normalizer is None:
        print("note: the demonstrations carry no random/optimal returns: no normalised return")
    print("compiling ...", flush=True)
    grid = Grid(train, hyperparams, specs, keys, chunk_blocks, devices)
    print(
        f"compiled in {grid.compile_seconds:.1f} s ({grid.num_cells} cells"
        f"{f', padded to {grid.num_padded}' if grid.num_padded != grid.num_cells else ''}, "
        f"{grid.iterations_per_chunk} iterations per chunk)",
        flush=True,
    )

    checkpoint_dir = out / "checkpoints"
    chunks_done, metrics_so_far, timing = 0, None, {"seconds": 0.0, "steps": 0}
    start = time.perf_counter()
    state, init_metrics = grid.init()
    init_metrics = grid.fetch(init_metrics)
    latest = _latest_checkpoint(checkpoint_dir)
    if resume_dir is not None and latest is not None:
        template = jax.eval_shape(lambda: grid.unpad(state))
        state = grid.place(restore_tree(latest / "state", template))
        with np.load(latest / "metrics.npz") as stored:
            metrics_so_far = {name.replace(":", "/"): stored[name] for name in stored.files}
        progress = json.loads((latest / "progress.json").read_text())
        chunks_done, timing = progress["chunks_done"], progress["timing"]
        print(f"resumed from {latest} (iteration {chunks_done * grid.iterations_per_chunk})")
    else:
        if resume_dir is not None:
            print(f"no checkpoint in {checkpoint_dir}: starting from the beginning")
        print(
            f"classifier phase done in {time.perf_counter() - start:.1f} s "
            f"(confidence MAE on D_u: "
            + ", ".join(
                f"{m} {np.mean(init_metrics['confidence/mae'][[c.method == m for c in cells]]):.3f}"
                for m in args.methods
            )
            + ")",
            flush=True,
        )

    num_chunks = num_evaluations // chunk_blocks
    reported_bad: set[int] = set()
    for chunk in range(chunks_done, num_chunks):
        chunk_start = time.perf_counter()
        state, chunk_metrics = grid.run_chunk(state)
        chunk_metrics = grid.fetch(chunk_metrics)
        seconds = time.perf_counter() - chunk_start
        timing["seconds"] += seconds
        timing["steps"] += len(cells) * grid.iterations_per_chunk * config.trpo.batch_size
        if metrics_so_far is None:
            metrics_so_far = chunk_metrics
        else:
            metrics_so_far = {
                name: np.concatenate([metrics_so_far[name], chunk_metrics[name]], axis=1)
                for name in chunk_metrics
            }
        iteration = (chunk + 1) * grid.iterations_per_chunk
        rate = timing["steps"] / timing["seconds"]
        remaining = (num_chunks - chunk - 1) * timing["seconds"] / (chunk + 1)
        bad = set(nonfinite_cells(metrics_so_far, args.eval_every).tolist())
        for index in sorted(bad - reported_bad):
            cell = cells[index]
            print(f"  ! cell {cell.method} seed {cell.seed} ({cell.setting}) diverged (NaN/inf)")
        reported_bad |= bad
        print(
            f"iter {iteration:5d}/{args.iterations}  "
            f"env steps {iteration * config.trpo.batch_size:,}/run  {rate:,.0f} steps/s  "
            f"ETA {format_seconds(remaining)}  "
            f"best {_best_cell(cells, chunk_metrics, normalizer)}",
            flush=True,
        )
        # Every process takes part in the gather and in orbax's save (it synchronises them).
        host_state = grid.fetch(state)
        _save_checkpoint(checkpoint_dir, chunk + 1, host_state, metrics_so_far, timing, writer)
        if writer and chunk + 1 < num_chunks:  # partial results; the last are written below
            _write_outputs(out, args, cells, metrics_so_far, init_metrics, normalizer, grid, timing)

    if not writer:
        return out
    metrics = {**metrics_so_far, **init_metrics}
    summary = _write_outputs(
        out, args, cells, metrics_so_far, init_metrics, normalizer, grid, timing
    )
    print()
    markdown = report.summary_markdown(summary, cells, metrics, _title(args, len(cells)))
    print(markdown.split("\n\nFinal return")[0])
    print(
        f"\ndone in {format_seconds(time.perf_counter() - start)} (+ compile); wrote "
        f"{out}/{{config.json,metrics.csv,curves.png,summary.md,summary.json,checkpoints/}}"
    )
    return out


def _title(args, num_cells: int) -> str:
    return f"{args.env}: {num_cells} runs, {args.iterations} iterations"


def _best_cell(cells, chunk_metrics, normalizer) -> str:
    from pngail_jax.report import normalize

    final = chunk_metrics["eval/return"][:, -1]
    if not np.isfinite(final).any():
        return "(none finite)"
    index = int(np.nanargmax(final))
    cell = cells[index]
    normalized = normalize(final[index], normalizer)
    extra = f" ({normalized:.2f})" if np.isfinite(normalized) else ""
    return f"{cell.method}/seed {cell.seed} {final[index]:.1f}{extra}"


def _latest_checkpoint(directory: Path):
    if not directory.exists():
        return None
    done = sorted(p for p in directory.glob("chunk_*") if (p / "progress.json").exists())
    return done[-1] if done else None


def _save_checkpoint(directory, chunks_done, host_state, metrics, timing, writer: bool):
    """Writes chunk_NNNN/ (state via orbax, metrics, progress last) and keeps the last two.

    Every process calls it (orbax synchronises processes); only the writer writes the rest.
    """
    from pngail_jax.checkpoint import save_tree

    path = directory / f"chunk_{chunks_done:04d}"
    save_tree(path / "state", host_state)
    if not writer:
        return
    np.savez(path / "metrics.npz", **{name.replace("/", ":"): v for name, v in metrics.items()})
    progress = {"chunks_done": chunks_done, "timing": timing}
    (path / "progress.json").write_text(json.dumps(progress))  # marks the checkpoint complete
    for old in sorted(directory.glob("chunk_*"))[:-2]:
        shutil.rmtree(old)


def _write_outputs(out, args, cells, metrics_so_far, init_metrics, normalizer, grid, timing):
    from pngail_jax import report
    from pngail_jax.grid import nonfinite_cells

    metrics = {**metrics_so_far, **init_metrics}
    report.write_metrics_csv(out / "metrics.csv", cells, metrics, normalizer)
    title = _title(args, len(cells))
    report.plot_curves(out / "curves.png", cells, metrics, normalizer, title)
    diverged = nonfinite_cells(metrics_so_far, args.eval_every)
    summary = report.summarize(
        cells,
        metrics,
        normalizer,
        timing["steps"] / timing["seconds"],
        grid.compile_seconds,
        excluded=diverged,
    )
    done = metrics["env_steps"].shape[1]
    notes = [
        f"Diverged (NaN/inf), left out of the means: {cells[i].method} seed {cells[i].seed} "
        f"({cells[i].setting})."
        for i in diverged
    ]
    if done < args.iterations:
        notes.append(f"Partial: {done} of {args.iterations} iterations so far.")
    if args.preset is None and args.iterations < 1000:
        notes.append(
            f"Smoke scale ({args.iterations} iterations); the paper's budget is "
            "`--preset paper` (5,000 iterations, GPU)."
        )
    report.write_summary(
        out, summary, report.summary_markdown(summary, cells, metrics, title, notes)
    )
    return summary


if __name__ == "__main__":
    main()
