"""``run_offline(OfflineRunConfig, out)``: the offline family (BC on the expert rows, BC on
every row, DWBC, ISW-BC) on a task's demonstrations, every method x seed in one compiled
``Grid`` of ``OfflineTrainer``, with the online sweep's evaluation and outputs: config.json,
metrics.csv, summary.json / summary.md (IQM and intervals, each method's probability of
beating BC on every row) and curves.png, so the rows join the sweep's tables.

A program of its own rather than sweep methods: the offline trainer has no rollout, learner
or discriminator schedule of the adversarial grid, so its config (gradient steps, batch size)
shares almost nothing with ``RunConfig``; what it shares (demonstrations, return range, split,
evaluation, summary) it takes from the same functions.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path

import jax
import numpy as np

from pngail_jax.analysis import plots, report
from pngail_jax.analysis.runs import (
    UntrustedRun,
    read_run_config,
    run_document,
    sealed_part,
    verify_run,
)
from pngail_jax.analysis.tracking import StepCounter, ticking
from pngail_jax.config import settings as env_settings
from pngail_jax.config.saved import provenance
from pngail_jax.config.task import task_bsc_eps
from pngail_jax.demos import DemonstrationError
from pngail_jax.grid import Grid, make_cells, nonfinite_cells, stack_cells
from pngail_jax.jobs.chunks import (
    Progress,
    blocks_per_chunk,
    format_seconds,
    intact_checkpoint,
    run_chunks,
    start,
)
from pngail_jax.jobs.demonstrations import input_files, load_or_make_demos, resolve_return_range
from pngail_jax.jobs.errors import RunError, refusals
from pngail_jax.jobs.offline_config import PROGRAM, OfflineRunConfig, load_offline_config
from pngail_jax.offline.family import OFFLINE
from pngail_jax.offline.trainer import METRICS_CSV_COLUMNS, OfflineConfig, OfflineTrainer
from pngail_jax.storage.integrity import CONFIG_SEAL, read_json, write_json, write_sealed
from pngail_jax.storage.outputs import claimed

__all__ = ["OfflineRunConfig", "load_offline_config", "run_offline"]


def run_offline(
    config: OfflineRunConfig,
    out: str | Path,
    overwrite: bool = False,
    resume: bool = False,
    *,
    command: Sequence[str] | None = None,
    allow_unsealed: bool = False,
) -> dict:
    """Trains the grid and writes its outputs into ``out``; returns the summary. Raises
    ``RunError`` with one line for a refused output directory or unusable inputs.
    ``command``: the command line recorded in ``config.json`` (default: this process's), as
    it can be run again; ``allow_unsealed``: resume a run whose config seal is missing (its
    config.json unchecked, which the output says).

    Each program keeps a checkpoint after every chunk (``checkpoints/<its methods>/``); with
    ``resume`` the run in ``out`` (begun with this ``config``, on the same input files)
    continues from them to the numbers of an uninterrupted run.

    The methods run in one compiled program per set of parts they need
    (``OFFLINE.program_groups``: both BCs together, DWBC, ISW-BC): a vmapped program computes
    every compiled part in every cell, and one mixed program ran 3.2 times as long as the
    separate ones together (benchmarks/offline_throughput.py, docs/methods.md)."""
    out = Path(out)
    with refusals(), claimed(out, PROGRAM, overwrite=overwrite, resume=resume) as claim:
        if resume:
            _check_resumable(out, config, allow_unsealed)
        env, demos, demos_path = _environment_and_demos(config)
        return_range, return_range_source = resolve_return_range(config, demos, env)
        trainer_config = config.trainer_config(demos.num_rows)
        resolved = {
            "demos_path": demos_path,
            "inputs": input_files(config.demonstrations, demos_path),
            "return_range": return_range,
            "return_range_source": return_range_source,
            "trainer": _json_config(dataclasses.replace(trainer_config, components=())),
        }
        document = {
            **run_document(PROGRAM, _json_config(config), resolved, provenance(command=command)),
            "complete": False,
        }
        if not resume:
            _begin(claim, out, document)
        cells = make_cells(config.methods, config.seeds, (config.label_ratio,),
                           (config.noise_std,))  # fmt: skip
        _announce(config, len(cells), trainer_config.num_demos or demos.num_rows)
        start_time = time.perf_counter()
        runs = [
            _run_group(config, OfflineTrainer(trainer, env, demos), group, return_range,
                       out / "checkpoints" / "+".join(methods), resume)
            for methods, trainer, group in _programs(config, trainer_config, cells)
        ]  # fmt: skip
        compile_seconds = sum(grid.compile_seconds for grid, _, _ in runs)
        progress = _joined(cells, runs)
        summary = _write_outputs(out, config, cells, progress, return_range, compile_seconds)
        _complete(out, document, trainer_config, progress, start_time, resume, command)
    print(f"-> {out}/{{config.json,metrics.csv,summary.md,summary.json,curves.png}}")
    return summary


def _announce(config: OfflineRunConfig, num_cells: int, num_rows: int) -> None:
    """The run's first line: its cells, task, budget and demonstration rows."""
    print(
        f"{num_cells} offline runs ({', '.join(config.methods)} x {config.seeds} seeds) on "
        f"{config.env}, {config.gradient_steps:,} gradient steps of {config.batch_size} "
        f"rows per batch, {num_rows} demonstration rows (label ratio {config.label_ratio:g})",
        flush=True,
    )


def _complete(
    out: Path, document, trainer_config, progress, start_time, resume, command=None
) -> None:
    """config.json marked complete, with the run's seconds (a resumed run keeps the document
    it began with, in its layout, this session's machine beside it); a document of the layout
    before ``runs.run_document`` gets the trainer's fields too, as it always did."""
    if resume:
        document = read_json(out / "config.json", "offline run config")
        document["resumed_provenance"] = provenance(command=command)
    if not read_run_config(document).trainer:  # the old layout wrote them as it ended
        document["trainer"] = _json_config(dataclasses.replace(trainer_config, components=()))
    seconds = {"wall_seconds": time.perf_counter() - start_time,
               "train_seconds": progress.timing["seconds"]}  # fmt: skip
    write_json(out / "config.json", {**document, "complete": True, **seconds})


def _programs(config: OfflineRunConfig, trainer_config: OfflineConfig, cells):
    """(methods, trainer config, cells) of each program the grid runs as (``program_groups``:
    one per set of compiled parts)."""
    for methods in OFFLINE.program_groups(config.methods):
        components = OFFLINE.parts(methods)
        group = [cell for cell in cells if cell.method in methods]
        yield methods, dataclasses.replace(trainer_config, components=components), group


def _begin(claim, out: Path, document: dict) -> None:
    """A new run's folder: claimed, its config sealed and written first, so that a run cut
    short can resume (and a config.json never exists without its seal)."""
    claim.prepare()
    write_sealed(out / "config.json", document, out / CONFIG_SEAL, sealed_part(document))


def _check_resumable(out: Path, config: OfflineRunConfig, allow_unsealed: bool = False) -> None:
    """RunError unless the run in ``out`` is one to continue with ``config``: trusted by
    ``runs.verify_run`` (its seal, unless ``allow_unsealed``, input files, metrics against
    summary) and begun with it."""
    try:
        for note in verify_run(out, f"cannot resume {out}", allow_unsealed=allow_unsealed):
            print(f"note: {note}", flush=True)
    except UntrustedRun as error:
        raise RunError(str(error)) from None
    if load_offline_config(out) != config:
        raise RunError(f"cannot resume {out}: it began with another config")


def _environment_and_demos(config: OfflineRunConfig):
    """(env, demonstrations, their path), or RunError naming what is wrong with them."""
    cells = len(config.methods) * config.seeds
    try:
        env = env_settings.make_env(config.env, config.settings, cells)
        demos, demos_path = load_or_make_demos(config, None, env)
        demos.check_env(env)  # before config.json is written, not in the first program
    except (DemonstrationError, FileNotFoundError, ImportError, ValueError) as error:
        raise RunError(f"demonstrations: {error}") from None
    if demos.confidence is None:
        raise RunError(f"{demos_path}: no confidences, which every offline method reads")
    if "ilid" in OFFLINE.parts(config.methods) and demos.trajectory_ids is None:
        raise RunError(
            f"{demos_path}: no trajectories (its rows carry no trajectory ids), and ILID selects "
            "rows by the states they lead to: drop ilid from --methods, or use a made set or "
            "the authors' Pendulum file"
        )
    return env, demos, demos_path


def _run_group(
    config: OfflineRunConfig, trainer: OfflineTrainer, cells, return_range, checkpoints, resume
):
    """One program's cells, compiled and run in chunks with a progress line and a checkpoint
    (in ``checkpoints``) each, from its last intact checkpoint when ``resume``: (grid, cells,
    Progress)."""
    trainer_config = trainer.config
    target = max(1, config.chunk_iterations // trainer_config.eval_every)
    chunk_blocks = blocks_per_chunk(trainer_config.num_evaluations, target)
    overrides = {
        "bsc_eps": task_bsc_eps(config.env),
        "ilid_discriminator_learning_rate": config.ilid_discriminator_learning_rate,
    }
    inputs = stack_cells(cells, jax.random.key(config.seed), overrides, family=OFFLINE)
    methods = ", ".join(dict.fromkeys(cell.method for cell in cells))
    counter = StepCounter()  # ILID's discriminators tell their steps from inside the program
    trainer.ilid.progress = counter
    with ticking(f"compiling {methods}"):
        grid = Grid(trainer, inputs, chunk_blocks)
    print(f"{methods}: {len(cells)} cells, compiled in {grid.compile_seconds:.1f} s", flush=True)
    checkpoint = intact_checkpoint(checkpoints) if resume else None
    if "ilid" in trainer_config.components and checkpoint is None:  # minutes, before step 1
        steps = trainer_config.ilid_discriminator_steps
        label = f"{methods}: ILID's two discriminators, {steps:,} steps each"
        with ticking(label, counter=counter, total=2 * steps):
            # saved at once: a run cut before its first chunk ends resumes after them
            state, progress = start(grid, checkpoint, save_to=checkpoints)
    else:
        state, progress = start(grid, checkpoint)
    steps_per_chunk = grid.num_cells * grid.iterations_per_chunk
    steps_per_chunk *= trainer_config.steps_per_iteration
    num_chunks = trainer_config.num_evaluations // chunk_blocks

    def line(progress, metrics) -> str:
        done = progress.chunks_done * grid.iterations_per_chunk
        done *= trainer_config.steps_per_iteration
        rate = steps_per_chunk / progress.last_chunk_seconds
        returns = metrics["eval/return"][:, -1]
        shown = report.normalize(returns, return_range) if return_range is not None else returns
        best = int(np.nanargmax(shown)) if np.isfinite(shown).any() else 0
        left = (num_chunks - progress.chunks_done) * progress.last_chunk_seconds
        return (
            f"  {methods}: step {done:9,d}/{config.gradient_steps:,}  {rate:9,.0f} gradient "
            f"steps/s (all its cells)  ETA {format_seconds(left)}  best {cells[best].method}/"
            f"seed {cells[best].seed} {shown[best]:.2f}"
        )

    run_chunks(
        grid, state, progress, num_chunks, steps_per_chunk=steps_per_chunk, line=line,
        checkpoints=checkpoints,
    )  # fmt: skip
    return grid, cells, progress


def _joined(cells, runs) -> Progress:
    """The groups' progress as one, their cells in ``cells``' order; a metric one group does
    not record (BC has no discriminator) is NaN in its cells."""
    order = [cell for _, group, _ in runs for cell in group]
    position = [order.index(cell) for cell in cells]

    def join(kind: str) -> dict:
        names = dict.fromkeys(n for _, _, progress in runs for n in getattr(progress, kind))
        joined = {}
        for name in names:
            parts = []
            for _, _, progress in runs:
                values = getattr(progress, kind)
                reference = next(iter(values.values()))
                parts.append(values.get(name, np.full(reference.shape, np.nan)))
            joined[name] = np.concatenate(parts)[position]
        return joined

    timing = {
        "seconds": sum(progress.timing["seconds"] for _, _, progress in runs),
        "steps": sum(progress.timing["steps"] for _, _, progress in runs),
    }
    # metrics.csv's wall clock: the training seconds at each chunk's end, counted from the
    # first group's start (the groups run one after another).
    chunk_seconds, offset = [], 0.0
    for _, _, progress in runs:
        chunk_seconds.append([offset + t for t in progress.timing["chunk_seconds"]])
        offset += progress.timing["seconds"]
    timing["chunk_seconds"] = chunk_seconds
    group_of = {cell: g for g, (_, group, _) in enumerate(runs) for cell in group}
    timing["group_of_cell"] = [group_of[cell] for cell in cells]
    return Progress(runs[0][2].chunks_done, join("init_metrics"), join("metrics"), timing)


def _json_config(config) -> dict:
    values = dataclasses.asdict(config)
    return {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}


def _write_outputs(out, config, cells, progress, return_range, compile_seconds) -> dict:
    """metrics.csv (``env_steps`` 0: no environment step is taken), summary.json / .md and
    curves.png; returns the summary."""
    metrics = {**progress.metrics, **progress.init_metrics}
    metrics["env_steps"] = np.zeros_like(progress.metrics["gradient_steps"], np.int64)
    _write_metrics(out / "metrics.csv", cells, metrics, return_range, progress.timing)
    excluded = nonfinite_cells(progress.metrics, config.eval_every)
    seconds = max(progress.timing["seconds"], 1e-9)
    baseline = "bc-all" if "bc-all" in config.methods else None
    summary = report.summarize(cells, metrics, return_range, 0.0, compile_seconds,
                               excluded, baseline)  # fmt: skip
    summary["gradient_steps"] = config.gradient_steps
    summary["gradient_steps_per_second"] = progress.timing["steps"] / seconds
    summary["offline/num_expert"] = float(np.mean(progress.init_metrics["offline/num_expert"]))
    title = (
        f"Offline methods on {config.env}: {config.gradient_steps:,} gradient steps, "
        f"{config.seeds} seeds"
    )
    notes = [
        f"Offline: no environment step; {summary['gradient_steps_per_second']:,.0f} gradient "
        f"steps/s over all {len(cells)} cells, {seconds:.0f} s of training. Expert set: D_c's "
        f"rows at confidence >= 0.5 (mean {summary['offline/num_expert']:.0f} rows per seed)."
    ]
    if "ilid/num_selected" in progress.init_metrics:
        summary["ilid"], note = _ilid_summary(progress.init_metrics, config.ilid_union)
        notes.append(note)
    if "dwbc/eval_d_expert" in progress.metrics:
        summary["dwbc"], note = _dwbc_summary(progress.metrics, config)
        notes.append(note)
    markdown = report.summary_markdown(summary, cells, metrics, title, notes)
    report.write_summary(out, summary, markdown)
    gradient = {**metrics, "env_steps": progress.metrics["gradient_steps"]}
    plots.plot_curves(out / "curves.png", cells, gradient, return_range, title, excluded,
                       xlabel="M gradient steps per run")  # fmt: skip
    print(markdown)
    return summary


def _ilid_summary(init_metrics: dict, union: str) -> tuple[dict, str]:
    """ILID's selection in the summary (means over its seeds), and the note that says it;
    with the released code's union, the share of its draws that are zero rows."""
    names = ["ilid/num_selected", "ilid/num_other", "ilid/selected_true_confidence",
             "ilid/other_true_confidence"]  # fmt: skip
    if "ilid/union_zero_share" in init_metrics:
        names.append("ilid/union_zero_share")
    ilid = {name.removeprefix("ilid/"): float(np.nanmean(init_metrics[name])) for name in names}
    note = (
        f"ILID's selection: a mean {ilid['num_selected']:.0f} of {ilid['num_other']:.0f} "
        "other rows per seed; their mean true confidence (which nothing read) "
        f"{ilid['selected_true_confidence']:.2f}, against {ilid['other_true_confidence']:.2f} "
        "for the rows it chose from."
    )
    if union == "released":
        note += (
            " Its union as its released code samples it (--ilid-union released): a mean "
            f"{ilid.get('union_zero_share', float('nan')):.6g} of its draws are zero rows."
        )
    return ilid, note


def _dwbc_summary(metrics: dict, config) -> tuple[dict, str]:
    """DWBC's discriminator at the last evaluation in the summary (means over the cells that
    ran it: its mean d on E and on O, the mean weights), and the note that says it."""
    names = ["d_expert", "d_other", "weight_expert", "weight_other"]
    last = {name: metrics[f"dwbc/eval_{name}"][:, -1] for name in names}
    dwbc = {name: float(np.nanmean(values)) for name, values in last.items()}
    dwbc["updates"] = config.gradient_steps // config.dwbc_discriminator_every
    note = (
        f"DWBC's discriminator ({dwbc['updates']:,} Adam steps) at the last evaluation: mean "
        f"d {dwbc['d_expert']:.2f} on E and {dwbc['d_other']:.2f} on O; mean weight of an "
        f"expert row's nll {dwbc['weight_expert']:.2f}, of an other row's "
        f"{dwbc['weight_other']:.2f}."
    )
    return dwbc, note


def _write_metrics(path, cells, metrics, return_range, timing) -> None:
    """metrics.csv by the sweep's writer, each cell with its own program's chunk ends as its
    wall clock (the programs run one after another), and the columns of
    ``offline.METRICS_CSV_COLUMNS`` whose metrics the run recorded (DWBC's discriminator at
    each evaluation, where DWBC ran)."""
    per_cell = [timing["chunk_seconds"][timing["group_of_cell"][i]] for i in range(len(cells))]
    extra = {column: name for column, name in METRICS_CSV_COLUMNS.items() if name in metrics}
    report.write_metrics_csv(path, cells, metrics, return_range, per_cell, extra)
