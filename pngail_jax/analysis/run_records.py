"""Run records: what a results table in the docs rests on, small enough to commit.

A record is a folder (``records/<name>/``) made from a sweep run's folder:

- ``record.json``: the name, the command, the commit, the machine (CPU model, devices,
  library versions, ``XLA_FLAGS``), the run's config (``config.json`` without its
  provenance), how far it got, its training and compile seconds, the digest of the metrics
  file, and each method's normalised returns per seed under both statistics: the headline
  (the mean over the last ``late_share`` of training) and the final evaluation;
- ``metrics.csv.gz``: the run's ``metrics.csv`` (the evaluations and the diagnostics columns),
  gzipped: every cell and iteration (``rows`` "all", the default), or with ``rows``
  "evaluated" the rows of the evaluated iterations and each cell's last alone, for a run
  whose every row would be megabytes (the diagnostics tables then average those rows).

No checkpoints, policies or plots: a 12-cell run of 5,000 iterations is about 2 MB with every
row, 35 cells of 5,000 iterations evaluated every tenth 0.6 MB with the evaluated ones.
``check_record`` reads a record back and verifies it: the metrics file against its digest,
whole against the config (every cell, every iteration the record says the run reached),
and both statistics recomputed from it against those the record states.
"""

from __future__ import annotations

import gzip
import math
import re
import shutil
from pathlib import Path

import numpy as np

from pngail_jax.analysis import stats
from pngail_jax.analysis.report import LATE_SHARE, iterations_per_cell, metrics_rows
from pngail_jax.analysis.runs import (
    STATISTICS,
    RunReadError,
    read_run_config,
    read_scored_rows,
    run_progress_numbers,
    run_return_range,
    run_scores,
    scores_of_metrics,
    verify_run,
)
from pngail_jax.config.learner import upgrade_learner_fields
from pngail_jax.config.released_files import PAPER_RETURN_RANGES
from pngail_jax.storage.integrity import (
    IntegrityError,
    atomic_path,
    file_digest,
    json_digest,
    read_json,
    write_json,
)
from pngail_jax.storage.outputs import output_owner

# 3: its digest and whether its run's seal was checked; 2: both statistics per seed (1 held
# the final evaluation only). ``record_upkeep.upgrade_record`` brings a format-2 record to 3.
FORMAT = 3
RECORD_FILE = "record.json"
METRICS_FILE = "metrics.csv.gz"
# What a record's metrics file keeps of its run's rows (``record.json``'s ``rows``; a record
# without the key keeps them all).
ROWS = ("all", "evaluated")
MACHINE_KEYS = (
    "cpu_model", "platform", "device_kind", "device_count", "process_count", "python",
    "libraries", "xla_flags",
)  # fmt: skip


class RecordError(Exception):
    """A run that cannot be recorded, or a record that does not check (the message names the
    file and the problem)."""


def _per_seed(scores: dict[str, np.ndarray]) -> dict[str, list[float | None]]:
    """Per method label, its seeds' scores (None for a diverged seed)."""
    return {
        label: [float(v) if np.isfinite(v) else None for v in values]
        for label, values in scores.items()
    }


def _confidence_errors(summary: dict) -> dict[str, list[float | None]]:
    """Per method label, each seed's confidence MAE on D_u as ``summary.json`` states it
    (None where it has none). The classifier is trained before the grid, so its error is
    not in metrics.csv: a record keeps it as the run stated it."""
    return {
        label: [
            seed.get("confidence_mae") for seed in sorted(row["per_seed"], key=lambda s: s["seed"])
        ]
        for label, row in summary.get("methods", {}).items()
        if row.get("per_seed")
    }


def _training_seconds(metrics_path: Path) -> float | None:
    """The run's training seconds so far: the largest ``wall_seconds`` of its metrics file."""

    rows = metrics_rows(metrics_path)
    seconds = [float(row["wall_seconds"]) for row in rows if row.get("wall_seconds")]
    return max(seconds) if seconds else None


def write_record(
    run_dir: Path,
    name: str,
    records: Path = Path("records"),
    *,
    allow_unsealed: bool = False,
    rows: str = "all",
) -> Path:
    """Records the sweep or offline run in ``run_dir`` as ``records/<name>/`` and checks it,
    once ``runs.verify_run`` trusts the run (its seal, unless ``allow_unsealed``; metrics.csv
    whole and agreeing with summary.json; its input files are not looked at), keeping the
    metrics ``rows`` (one of ``ROWS``). A record of that name already there is replaced only
    if it records the same run (same config and commit); anything else in the way is
    refused. Returns the record's folder."""

    run_dir = Path(run_dir)
    check_name(name)
    _check_rows_choice(rows)
    notes, config, summary, scores = _verified_run(run_dir, allow_unsealed)
    provenance = config.get("provenance", {})
    progress = run_progress_numbers(run_dir)
    record = {
        "format": FORMAT,
        "name": name,
        "program": f"experiments.{output_owner(run_dir)}",
        "command": provenance.get("command_line"),
        "commit": provenance.get("git_commit"),
        "machine": {key: provenance.get(key) for key in MACHINE_KEYS},
        "config": {key: value for key, value in config.items() if key != "provenance"},
        "complete": summary.get("complete") is not False,
        # What metrics.csv holds (a summary may be a chunk behind it, after a stop between
        # the two writes; check_record recomputes this from the recorded file).
        "iterations_done": max(iterations_per_cell(run_dir / "metrics.csv").values()),
        "iterations": progress[1] if progress else planned_iterations(config),
        # Made with --allow-unsealed: the run's config.json was taken as it stood.
        "unsealed": bool(notes),
        "training_seconds": _training_seconds(run_dir / "metrics.csv"),
        "compile_seconds": summary.get("compile_seconds"),
        "late_share": LATE_SHARE,
        "rows": rows,
        **{statistic_key(name): _per_seed(values) for name, values in scores.items()},
        "confidence_mae": _confidence_errors(summary),
    }
    folder = Path(records) / name
    _check_replaceable(folder, record)
    folder.mkdir(parents=True, exist_ok=True)
    metrics = folder / METRICS_FILE
    with (run_dir / "metrics.csv").open("rb") as source:
        write_metrics(metrics, source, kept_lines(run_dir / "metrics.csv", rows))
    write_json(folder / RECORD_FILE, sealed_record({**record, "metrics": metrics_entry(metrics)}))
    check_record(folder)
    return folder


def _verified_run(run_dir: Path, allow_unsealed: bool):
    """The run in ``run_dir`` once ``runs.verify_run`` trusts it (its notes printed): its
    notes, config.json, summary.json and per-seed scores under each statistic."""
    try:  # verify_run refuses a folder of neither program
        notes = verify_run(run_dir, str(run_dir), allow_unsealed=allow_unsealed,
                           check_inputs=False)  # fmt: skip
        for note in notes:
            print(f"note: {note}")
        config = read_json(run_dir / "config.json", "run config")
        summary = read_json(run_dir / "summary.json", "run summary")
        scores = {name: run_scores(run_dir, name)[1] for name in STATISTICS}
    except FileNotFoundError as error:
        raise RecordError(f"{run_dir}: {Path(error.filename).name} is missing") from None
    except (OSError, IntegrityError, RunReadError) as error:
        raise RecordError(str(error)) from None
    return notes, config, summary, scores


def metrics_entry(metrics: Path) -> dict:
    """``record.json``'s ``metrics``: the written metrics file's name, size and SHA-256."""
    return {"file": METRICS_FILE, "bytes": metrics.stat().st_size, "sha256": file_digest(metrics)}


def _check_rows_choice(rows: str) -> None:
    if rows not in ROWS:
        raise RecordError(f"rows {rows!r}: give one of {', '.join(ROWS)}")


def kept_lines(metrics: Path, rows: str) -> set[int] | None:
    """The line numbers (0 the header) of the metrics file ``metrics`` (``metrics.csv`` or a
    record's gzipped one) that a record keeping ``rows`` keeps: None for "all"; for
    "evaluated" the header, every row with an evaluation and each cell's last row."""
    _check_rows_choice(rows)
    if rows == "all":
        return None
    last = iterations_per_cell(metrics)
    kept = {0}
    for number, row in enumerate(metrics_rows(metrics), start=1):
        cell = (row["method"], row["setting"], int(row["seed"]))
        if row.get("eval_return") not in (None, "") or int(row["iteration"]) == last[cell]:
            kept.add(number)
    return kept


def write_metrics(path: Path, source, kept: set[int] | None) -> None:
    """Writes the lines of the binary file ``source`` numbered in ``kept`` (every line when
    None), byte for byte, to ``path`` gzipped, atomically, with no file name and no time in
    the gzip header: the same run gives the same bytes. The metrics files hold no line
    breaks inside a field, so a line is a row."""
    with atomic_path(path) as temporary, temporary.open("wb") as raw:
        with gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as target:
            if kept is None:
                shutil.copyfileobj(source, target)
                return
            for number, line in enumerate(source):
                if number in kept:
                    target.write(line)


def sealed_record(record: dict) -> dict:
    """``record`` with its ``digest``: the SHA-256 of everything else in it, so that what
    ``check_record`` cannot recompute from the metrics (the commit, the command, the machine,
    each seed's classifier error) cannot change unseen either."""
    unsealed = {key: value for key, value in record.items() if key != "digest"}
    return {**unsealed, "digest": json_digest(unsealed)}


def planned_iterations(config: dict) -> int | None:
    """The iterations a run's ``config.json`` (or a record's config) plans: the sweep's
    ``iterations``, the offline program's gradient steps over its steps per iteration."""
    return read_run_config(config).planned_iterations


def check_name(name: str) -> None:
    """RecordError unless ``name`` is a plain folder name a docs marker can name."""
    if not name or not re.fullmatch(r"[\w.-]+", name) or name.startswith("."):
        raise RecordError(f"record name {name!r}: give a plain folder name, e.g. hopper-cpu")


def _check_replaceable(folder: Path, record: dict) -> None:
    """RecordError unless ``folder`` is new, empty, or a record of the same run."""
    if not folder.exists():
        return
    if not folder.is_dir():
        raise RecordError(f"{folder} is a file: give another --name")
    found = {path.name for path in folder.iterdir()}
    if not found:
        return
    if not found <= {RECORD_FILE, METRICS_FILE}:
        strangers = ", ".join(sorted(found - {RECORD_FILE, METRICS_FILE}))
        raise RecordError(f"{folder} holds files a record does not ({strangers}): not replaced")
    try:
        old = read_json(folder / RECORD_FILE, "run record")
    except (OSError, IntegrityError) as error:
        raise RecordError(
            f"{folder}: not replaced, its record.json is unreadable ({error})"
        ) from None
    if old.get("config") != record["config"] or old.get("commit") != record["commit"]:
        raise RecordError(
            f"{folder} records another run (its config or commit differs): give another --name"
        )


def check_record(folder: Path) -> dict:
    """Verifies the record in ``folder`` and returns its ``record.json``: the metrics file is
    the one recorded (size and SHA-256), whole (every cell of the config, to the iteration the
    record says), and gives both statistics the record states. RecordError otherwise."""
    folder = Path(folder)
    try:
        record = read_json(folder / RECORD_FILE, "run record")
    except FileNotFoundError:
        raise RecordError(f"{folder} holds no run record ({RECORD_FILE} is missing)") from None
    except (OSError, IntegrityError) as error:
        raise RecordError(f"{folder / RECORD_FILE}: unreadable ({error})") from None
    if not isinstance(record, dict) or record.get("format") != FORMAT:
        found = record.get("format") if isinstance(record, dict) else None
        remedy = (
            f": bring it up to date with python -m experiments.record --upgrade {folder}"
            if found == FORMAT - 1
            else ""
        )
        raise RecordError(f"{folder / RECORD_FILE}: not a run record of format {FORMAT}{remedy}")
    if record.get("digest") != json_digest({k: v for k, v in record.items() if k != "digest"}):
        raise RecordError(
            f"{folder / RECORD_FILE} was changed since it was written (its digest differs): "
            "record the run again"
        )
    metrics = folder / METRICS_FILE
    expected = record.get("metrics", {})
    if not metrics.is_file():
        raise RecordError(f"{metrics} is missing")
    if metrics.stat().st_size != expected.get("bytes") or file_digest(metrics) != expected.get(
        "sha256"
    ):
        raise RecordError(f"{metrics} differs from what the record wrote (size or SHA-256)")
    done, planned = record.get("iterations_done"), record.get("iterations")
    progress = (done, planned) if isinstance(done, int) and isinstance(planned, int) else None
    if record.get("late_share") != LATE_SHARE:
        raise RecordError(
            f"{folder / RECORD_FILE}: its late average is over the last "
            f"{record.get('late_share')} of training, this version's over {LATE_SHARE}: "
            "record the run again"
        )
    _check_config_facts(folder, record)
    settings = read_run_config(record["config"]).settings
    for name in STATISTICS:
        try:
            scores = scores_of_metrics(metrics, settings, progress, name)
        except RunReadError as error:
            raise RecordError(str(error)) from None
        if _per_seed(scores) != record.get(statistic_key(name)):
            raise RecordError(
                f"{folder / RECORD_FILE}: its {statistic_key(name)} differs from that of "
                f"{METRICS_FILE}"
            )
    _check_kept_rows(folder, record)
    _check_confidence_errors(folder, record)
    return record


def _check_kept_rows(folder: Path, record: dict) -> None:
    """RecordError unless the record's ``rows`` is one of ``ROWS`` and a record of the
    evaluated rows holds no other row (a record of every row is whole by its digest and
    ``_check_config_facts``)."""
    rows = record.get("rows", "all")
    if rows not in ROWS:
        raise RecordError(f"{folder / RECORD_FILE}: rows {rows!r} is not one of {', '.join(ROWS)}")
    if rows == "all":
        return
    metrics = folder / METRICS_FILE
    total = 1 + sum(1 for _ in metrics_rows(metrics))
    if len(kept_lines(metrics, rows)) != total:
        raise RecordError(
            f"{metrics} holds rows without an evaluation before each cell's last, which a "
            "record of the evaluated rows drops: the record or its metrics were edited"
        )


def _check_config_facts(folder: Path, record: dict) -> None:
    """RecordError unless the facts of the record's config are those its metrics file
    gives: every normalised return is its evaluation through the config's return range
    (``runs.read_scored_rows``), the methods, the seeds of each, the label ratios and
    confidence noises, the iterations done (and the environment steps each took, for a
    sweep) and planned, whether it is complete, and the task, where the return range is the
    paper's Table 3 row of an authors' file (that row's task is the config's)."""

    where = folder / RECORD_FILE
    config = record.get("config")
    if not isinstance(config, dict):
        raise RecordError(f"{where}: no config")
    view = read_run_config(config)
    settings = view.settings
    metrics = folder / METRICS_FILE
    try:
        return_range = run_return_range(config)
        read_scored_rows(metrics, return_range)
        cells, ratios, noises, reached, steps = _metrics_facts(metrics)
    except RunReadError as error:
        raise RecordError(str(error)) from None
    except (KeyError, ValueError, TypeError, EOFError, OSError) as error:
        raise RecordError(f"{metrics} is damaged ({error})") from None

    def refuse(fact: str, stated, found) -> None:
        raise RecordError(
            f"{where}: its config says {fact} {stated!r}, its {METRICS_FILE} {found!r}: the "
            "record or its metrics were edited"
        )

    methods = sorted({method for method, _ in cells})
    if sorted(settings.get("methods") or []) != methods:
        refuse("methods", settings.get("methods"), methods)
    seeds = settings.get("seeds")
    for (method, _), found in cells.items():
        if found != set(range(seeds if isinstance(seeds, int) else -1)):
            refuse(f"{method} has seeds", seeds, len(found))
    stated_ratios, stated_noises = view.label_ratios, view.noise_stds
    if sorted(map(float, stated_ratios or [])) != sorted(ratios):
        refuse("label ratios", stated_ratios, sorted(ratios))
    if sorted(map(float, stated_noises or [])) != sorted(noises):
        refuse("confidence noises", stated_noises, sorted(noises))
    if record.get("iterations_done") != reached:
        refuse("iterations done", record.get("iterations_done"), reached)
    planned = view.planned_iterations
    if record.get("iterations") != planned or record.get("complete") is not (reached == planned):
        raise RecordError(
            f"{where}: it says {record.get('iterations_done')!r} of {record.get('iterations')!r} "
            f"iterations (complete: {record.get('complete')!r}), its config plans {planned!r} and "
            f"its {METRICS_FILE} ends at {reached}: the record or its metrics were edited"
        )
    if view.program != "offline":
        _check_steps(settings.get("settings") or {}, steps, refuse)
    _check_task(where, config, return_range)


def _check_steps(rollout: dict, steps: dict, refuse) -> None:
    """A sweep's environment steps at each iteration (``steps``: iteration -> the set of
    values its metrics give) against its rollout's ``num_envs * unroll_length`` an
    iteration; ``refuse(fact, stated, found)`` at the first that differs."""
    if not isinstance(rollout.get("num_envs"), int):
        return
    per_iteration = rollout["num_envs"] * rollout.get("unroll_length", 0)
    wrong = [i for i, found in steps.items() if found != {i * per_iteration}]
    if wrong:
        refuse(
            f"{per_iteration} environment steps an iteration; at iteration {wrong[0]}",
            wrong[0] * per_iteration,
            sorted(steps[wrong[0]]),
        )


def _metrics_facts(metrics: Path):
    """What a record's metrics file says of its run: the seeds of each (method, setting),
    the label ratios and noises, the last iteration, and the environment steps at each."""

    cells: dict[tuple[str, str], set[int]] = {}
    ratios, noises, reached, steps = set(), set(), 0, {}
    for row in metrics_rows(metrics):
        cells.setdefault((row["method"], row["setting"]), set()).add(int(row["seed"]))
        ratios.add(float(row["label_ratio"]))
        noises.add(float(row["noise"]))
        iteration = int(row["iteration"])
        reached = max(reached, iteration)
        steps.setdefault(iteration, set()).add(int(float(row["env_steps"])))
    return cells, ratios, noises, reached, steps


def _check_task(where: Path, config: dict, return_range: list[float] | None) -> None:
    """RecordError unless a record of an authors' file whose return range is the paper's
    Table 3 row has that row's return range and that file's task (on a made set the metrics carry no
    witness of the task: the record's digest alone keeps it)."""

    view = read_run_config(config)
    settings, source = view.settings, view.return_range_source
    demos = Path(str(settings.get("demos") or "")).name.removesuffix("_mixture.npy")
    if source == "paper Table 3" and demos in PAPER_RETURN_RANGES:
        task = str(settings.get("env"))
        if list(PAPER_RETURN_RANGES[demos]) != return_range:
            raise RecordError(
                f"{where}: its return range {return_range} is not the paper's Table 3 row of "
                f"{demos}, {list(PAPER_RETURN_RANGES[demos])}, which it names as its source: the "
                "record was edited"
            )
        if task.split("-v")[0] != demos.split("-v")[0]:
            raise RecordError(
                f"{where}: its config says the task is {task}, its demonstrations and "
                f"return range (which its {METRICS_FILE} scores agree with) are {demos}'s: the "
                "record was edited"
            )


def _check_confidence_errors(folder: Path, record: dict) -> None:
    """RecordError unless the record's ``confidence_mae`` (where it has one) holds, for
    methods of the record, one number (or None) per seed."""
    errors = record.get("confidence_mae")
    if errors is None:
        return
    seeds = record[statistic_key("final")]
    if not isinstance(errors, dict) or any(
        label not in seeds
        or not isinstance(values, list)
        or len(values) != len(seeds[label])
        or not all(v is None or isinstance(v, (int, float)) for v in values)
        for label, values in errors.items()
    ):
        raise RecordError(
            f"{folder / RECORD_FILE}: its confidence_mae is not one number per seed of its methods"
        )


def statistic_key(statistic: str) -> str:
    """record.json's key of a statistic's per-seed scores."""
    return f"{statistic}_normalized_return"


def describe(record: dict) -> str:
    """One paragraph for the terminal: what the record holds."""
    finals = record[statistic_key("final")]
    cells = sum(len(values) for values in finals.values())
    how_far = (
        "complete"
        if record["complete"]
        else f"{record['iterations_done']:,} of {record['iterations']:,} iterations"
    )
    unsealed = (
        "; made with --allow-unsealed (its run's config.json unchecked)"
        if record.get("unsealed")
        else ""
    )
    env = read_run_config(record["config"]).settings.get("env")
    return (
        f"{record['name']}: {env}, {len(finals)} methods, "
        f"{cells} runs, {how_far}; commit {str(record['commit'])[:10]}, "
        f"{record['machine'].get('cpu_model') or 'CPU not recorded'}; "
        f"metrics {record['metrics']['bytes']:,} bytes"
        f"{', its evaluated rows' if record.get('rows') == 'evaluated' else ''}{unsealed}"
    )


# Keys of a run config that do not change its numbers (or say where its files were, how
# long the run took, or on what machine).
_NOT_NUMBERS = ("demos", "conf", "resolved", "log", "chunk_iterations", "cpu_devices",
                "preset_name", "provenance", "resumed_provenance", "complete", "wall_seconds",
                "train_seconds", "demonstrations", "input_files")  # fmt: skip


def config_differences(
    config: dict, record: dict, sweep_defaults: dict, offline_defaults: dict | None = None
) -> list[str]:
    """The config fields in which a run (its ``config.json``) differs from the record's run,
    leaving out those that do not change the numbers: the top-level fields of a sweep's, the
    settings (``config``) of an offline run's with its return range and trainer fields. A field
    one side lacks (a record from before the field existed) reads as its value in
    ``sweep_defaults``, a default ``RunConfig``'s ``to_dict()``, or for an offline run in
    ``offline_defaults``, a default ``OfflineRunConfig``'s fields (which the caller, above the
    trainers, makes: this module imports no JAX). An offline run's trainer fields and
    return range are compared only where both sides have them: a run writes its trainer's
    fields when it finishes, so a run cut short has none yet."""

    def fields(document: dict) -> dict:
        view = read_run_config(document)
        if view.program != "offline":  # a sweep's of an older layout read in today's
            return upgrade_learner_fields(view.settings)
        return {
            **{f"{part}.{key}": value for part, values in (("config", view.settings),
               ("trainer", view.trainer)) for key, value in values.items()},
            "return_range": view.return_range,
        }  # fmt: skip

    mine, reference = fields(config), fields(record["config"])
    not_numbers = set(_NOT_NUMBERS) | {f"config.{key}" for key in _NOT_NUMBERS}
    keys = sorted((set(mine) | set(reference)) - not_numbers)
    offline = read_run_config(config).program == "offline"
    defaults = sweep_defaults
    if offline:
        defaults = {f"config.{key}": value for key, value in (offline_defaults or {}).items()}

    def value(document: dict, key: str):
        return document[key] if key in document else defaults.get(key)

    def written_later(key: str) -> bool:  # an offline run's trainer part, at its end
        partial = key.startswith("trainer.") or key == "return_range"
        return offline and partial and (mine.get(key) is None or reference.get(key) is None)

    return [
        key for key in keys if not written_later(key) and value(mine, key) != value(reference, key)
    ]


def check_comparable(run_dirs, record: dict) -> list[str]:
    """RecordError unless each run in ``run_dirs`` can be set against ``record``: a run of
    the record's program (a sweep's record against sweeps, an offline one against offline
    runs), of the record's task, at the iterations the record reached (a late average or a
    final evaluation of a shorter or longer training is another figure). Returns the lines
    that say what is unfinished on either side (compared all the same, like with like)."""

    program = str(record.get("program", "")).removeprefix("experiments.")
    task = read_run_config(record["config"]).settings.get("env")
    done, planned = record.get("iterations_done"), record.get("iterations")
    notes = []
    if not record.get("complete"):
        notes.append(f"the record {record['name']} is unfinished: {done:,} of {planned:,} "
                     "iterations")  # fmt: skip
    for run_dir in run_dirs:
        run_dir = Path(run_dir)
        owner = output_owner(run_dir)
        if owner != program:
            raise RecordError(
                f"{run_dir} is a run of experiments.{owner}, the record {record['name']} of "
                f"experiments.{program}: compare a run of the record's program"
            )
        config = read_json(run_dir / "config.json", "run config")
        if read_run_config(config).settings.get("env") != task:
            continue  # another task: expected_rows reads only the record's
        progress = run_progress_numbers(run_dir, config)
        if progress is None:
            raise RecordError(f"{run_dir}: its progress is unknown (no summary.json to say it)")
        if progress[0] != done:
            raise RecordError(
                f"{run_dir} reached {progress[0]:,} of {progress[1]:,} iterations, the record "
                f"{record['name']} {done:,} of {planned:,}: compare like with like (finish the "
                "run with --resume, or a record of the same length)"
            )
        if progress[0] != progress[1]:
            notes.append(f"{run_dir} is unfinished: {progress[0]:,} of {progress[1]:,} iterations")
    return notes


def expected_rows(scores, record: dict) -> list[dict]:
    """Per method of the record: is the IQM of your seeds' scores (``scores``, a
    ``compare.Scores``, under its statistic) inside the record's 95% bootstrap interval of its
    IQM over seeds under the same statistic, and by how much is it outside. RecordError when
    your runs hold no run of the record's task."""

    task = read_run_config(record["config"]).settings.get("env")
    if task not in scores.tasks:
        raise RecordError(
            f"the record {record['name']} is of {task}; your runs are of {', '.join(scores.tasks)}"
        )
    rows = []
    for method, seeds in record[statistic_key(scores.statistic)].items():
        reference = stats.seed_summary([math.nan if v is None else v for v in seeds])
        row = {
            "method": method,
            "reference_iqm": reference["iqm"],
            "reference_ci95": reference["ci95"],
            "reference_seeds": reference["num_seeds"],
        }
        yours = scores.values.get(method, {}).get(task)
        if yours is None:
            rows.append({**row, "verdict": "not in your runs"})
            continue
        mine = stats.seed_summary(yours)
        low, high = reference["ci95"]
        estimate = mine["iqm"]
        spread = rerun_spread(seeds, mine["num_seeds"])
        row["rerun_spread"] = spread
        row["within_rerun_spread"] = bool(abs(estimate - reference["iqm"]) <= spread)
        if not math.isfinite(estimate):
            verdict, distance = "no finite return", math.nan
        elif low <= estimate <= high:
            verdict, distance = "within", 0.0
        elif estimate < low:
            verdict, distance = "below", low - estimate
        else:
            verdict, distance = "above", estimate - high
        rows.append({**row, "your_iqm": estimate, "your_seeds": mine["num_seeds"],
                     "verdict": verdict, "outside_by": distance})  # fmt: skip
    return rows


def rerun_spread(seeds, num_seeds: int, num_draws: int = 2000) -> float:
    """How far the IQM of a re-run of ``num_seeds`` seeds lands from the record's IQM, as a
    re-run shows it: the 95th percentile of |IQM(a draw of ``num_seeds`` of the record's seeds,
    without replacement) - IQM(all of them)| over ``num_draws`` draws (a fixed seed). NaN when
    the record has no more seeds than the re-run (then no draw differs from it)."""

    values = np.asarray([v for v in seeds if v is not None and math.isfinite(v)], float)
    if num_seeds < 1 or values.size <= num_seeds:
        return math.nan
    rng = np.random.default_rng(0)
    whole = stats.iqm(values)
    shifts = [
        abs(stats.iqm(rng.choice(values, num_seeds, replace=False)) - whole)
        for _ in range(num_draws)
    ]
    return float(np.percentile(shifts, 95))


def expected_markdown(
    rows: list[dict],
    record: dict,
    differences: list[str],
    statistic: str,
    notes: list[str] = (),
) -> str:
    """The ``--expected`` table: your IQM against the record's interval, per method, both
    under ``statistic`` (a key of ``compare.STATISTICS``); ``notes`` (``check_comparable``'s:
    what is unfinished) above it."""

    env = read_run_config(record["config"]).settings.get("env")
    lines = [
        f"## Against the record {record['name']} ({env}, commit {str(record['commit'])[:10]})",
        "",
        f"Score: {STATISTICS[statistic]}. The IQM of your seeds against the record's IQM and "
        "its 95% bootstrap interval over its seeds. Outside it is a difference to look at, not "
        "proof of one: a run on another machine is another draw (docs/sweep.md, what is "
        "reproducible).",
        "",
    ]
    lines += [f"Note: {note}." for note in notes] + ([""] if notes else [])
    if differences:
        lines += [f"Your config differs from the record's in: {', '.join(differences)}.", ""]
    lines += ["| method | yours (IQM, seeds) | record: IQM [95% CI] (seeds) | verdict |",
              "|---|---:|---:|---|"]  # fmt: skip
    for row in rows:
        low, high = row["reference_ci95"]
        reference = f"{row['reference_iqm']:.2f} [{low:.2f}, {high:.2f}] ({row['reference_seeds']})"
        if "your_iqm" not in row:
            lines.append(f"| {row['method']} | - | {reference} | {row['verdict']} |")
            continue
        verdict = row["verdict"] + (
            f" by {row['outside_by']:.2f}" if row["verdict"] in ("below", "above") else ""
        )
        if math.isfinite(row["rerun_spread"]):
            side = "within" if row["within_rerun_spread"] else "beyond"
            verdict += (
                f"; {side} the spread a re-run of {row['your_seeds']} seeds shows "
                f"(+-{row['rerun_spread']:.2f}, from the record's seeds)"
            )
        lines.append(
            f"| {row['method']} | {row['your_iqm']:.2f} ({row['your_seeds']}) | {reference} | "
            f"{verdict} |"
        )
    return "\n".join(lines) + "\n"


def seed_values(seeds: list[float | None]) -> np.ndarray:
    """A record's per-seed list as float[seeds], NaN for a seed without a score."""
    return np.asarray([math.nan if v is None else v for v in seeds], float)
