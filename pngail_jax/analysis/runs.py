"""Reading a run folder (a sweep's or the offline program's) and deciding whether to trust
it: its settings, how far it got, each seed's score under a statistic from its metrics.csv
(checked whole), and ``verify_run``, the one check every program makes before it trusts an
earlier run (resume, adopt, compare, the paper's page, records): the config's seal, the input
files' digests, metrics.csv whole and agreeing with summary.json, the policies' digests.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import numpy as np

from pngail_jax.analysis.report import (
    HEADLINE,
    LATE_LABEL,
    iterations_per_cell,
    late_evaluations,
    metrics_rows,
    read_evaluations,
    seed_figures,
    summary_return_range,
)
from pngail_jax.storage.integrity import (
    CONFIG_SEAL,
    IntegrityError,
    changed_inputs,
    read_json,
    sealed_differences,
    verify_manifest,
)
from pngail_jax.storage.outputs import output_owner


class RunReadError(Exception):
    """A run folder or metrics file that cannot be read as a run (the message names it)."""


STATISTICS = {  # what a score is, as the tables and plots say it
    "late_average": f"normalised return, mean over the {LATE_LABEL}",
    "final": "final normalised return (the last evaluation)",
}
RUN_PROGRAMS = ("sweep", "offline")  # the programs whose runs compare (and records) read


# What an offline run's seal covered in the layout before ``run_document`` (config.json's
# parts fixed when the run began; it added the trainer's fields, its seconds and "complete"
# when it ended).
OFFLINE_SEALED = ("program", "config", "demonstrations", "input_files", "normalizer",
                  "normalizer_source")  # fmt: skip
# What the seal leaves out in the layout of ``run_document``: what a run writes as it runs or
# ends (where it ran, whether it is complete, its seconds). Everything else is fixed when it
# begins, a key added by hand included.
RUN_UNSEALED = ("provenance", "resumed_provenance", "complete", "wall_seconds", "train_seconds")
# Each program's method family: the sweep's adversarial methods, the offline program's,
# and reinforcement learning on the true reward (no demonstrations): train_rl's, and
# make_demos' learner whose checkpoints the demonstrations are rolled out from.
FAMILIES = {"sweep": "adversarial", "offline": "offline", "train_rl": "reinforcement",
            "make_demos": "reinforcement"}  # fmt: skip


def run_document(program: str, config: dict, resolved: dict, provenance: dict) -> dict:
    """The one layout of a run's ``config.json``, whichever program writes it (``sweep``:
    ``jobs.record.write_config``; ``offline``: ``jobs.offline.run_offline``; ``train_rl``:
    ``jobs.train_rl.TrainRLConfig.document``; ``make_demos``:
    ``jobs.make_demos_run.making_document``)::

        {"program": "sweep" | "offline" | "train_rl" | "make_demos",
         "family": "adversarial" | "offline" | "reinforcement",  # what it ran (FAMILIES)
         "config": {the job config's fields: RunConfig's, OfflineRunConfig's,
                    TrainRLConfig's or MakeDemosConfig's (with train_rl's and
                    make_demos' "argv", the flags --resume reads)},
         "resolved": {what the config resolved to when the run began: "demos_path",
                      "inputs" (each input file's integrity.file_record), "return_range"
                      (random, optimal) and "return_range_source", "trainer" (the
                      trainer's static config), and the program's own: a sweep's
                      "methods" (their presets), "physics", "action_scale", "num_demos",
                      "bsc_eps"; train_rl's and make_demos' are "env_options",
                      "rollout" and "hyperparams" alone},
         "provenance": {where and with what it ran: provenance()},
         ...}  # the offline program adds "complete", its seconds and, when resumed,
               # "resumed_provenance" as it ends

    The seal covers all but ``RUN_UNSEALED``: ``program``, ``family``, ``config`` and
    ``resolved``, and any key added by hand.
    Files of the two layouts before this one still read (``read_run_config``) and resume
    as they are: a resume never writes a run's config.json in another layout (train_rl's
    flat layouts: ``jobs.train_rl.flat_document``)."""
    return {
        "program": program,
        "family": FAMILIES[program],
        "config": config,
        "resolved": resolved,
        "provenance": provenance,
    }


@dataclasses.dataclass(frozen=True)
class RunConfigView:
    """A run's ``config.json`` (or a record's ``config``), whichever program wrote it and in
    whichever layout, read the same way (``read_run_config``)."""

    program: str  # "sweep", "offline" or (its seal alone is read) "train_rl", "make_demos"
    settings: dict  # env, methods, seeds, demos, ...: what the run was asked to do
    sealed: dict  # what the run's config seal covers
    inputs: dict  # the input files' records (integrity.file_record), by name
    # The normalised return's ends, (random, optimal), as written (the key "normalizer" in
    # the layouts before run_document; run_return_range checks them), and where they came
    # from ("paper Table 3", ...). "normalizer" in the code is the policy's observation
    # statistics (rl.ObservationNormalizer) alone.
    return_range: object
    return_range_source: str | None
    label_ratios: list  # the grid's label ratios (the offline program runs one)
    noise_stds: list  # the grid's confidence noises (the offline program runs one)
    planned_iterations: int | None  # the iterations it plans, where the config says
    complete: bool | None  # the offline program's "complete" (a sweep's is in summary.json)
    trainer: dict  # the offline trainer's fields ({} for a sweep, and before an old run ends)


def read_run_config(document: dict) -> RunConfigView:
    """The one reader of a run's ``config.json`` (or of a run record's ``config``, the same
    document without its provenance): every reader of run folders and records goes through
    it, so the layouts on disk are told apart here alone.

    Today's layout is ``run_document``'s (marked by its ``family``). The two before it are
    read as they always were (their runs resume, compare and reproduce unchanged):

    - ``experiments.sweep``'s, flat: the ``RunConfig``'s fields at the top (``env``,
      ``methods``, ``seeds``, ``label_ratios``, ``noise_stds``, ``iterations``, ...),
      ``resolved`` (``inputs``, ``normalizer``, ``normalizer_source``, the methods' presets,
      ``adversarial``, ...) and ``provenance`` (where it ran; not sealed);
    - ``experiments.offline``'s, nested: ``{"program": "offline", "config": {the
      OfflineRunConfig's fields}, "demonstrations", "input_files", "normalizer",
      "normalizer_source", "provenance", "trainer", "complete", ...}``, of which
      ``OFFLINE_SEALED`` is sealed when it begins.
    """
    program = "offline" if document.get("program") == "offline" else "sweep"
    if "family" in document:  # the mark of run_document's layout (config.saved.is_run_document)
        named = document.get("program")
        known = isinstance(named, str) and named in FAMILIES
        return _read_run_document(document, named if known else program)
    if program == "offline":
        settings = document.get("config") or {}
        return RunConfigView(
            program="offline",
            settings=settings,
            sealed={key: document[key] for key in OFFLINE_SEALED if key in document},
            inputs=document.get("input_files") or {},
            return_range=document.get("normalizer"),
            return_range_source=document.get("normalizer_source"),
            label_ratios=[settings.get("label_ratio")],
            noise_stds=[settings.get("noise_std")],
            planned_iterations=_offline_planned(settings),
            complete=document.get("complete"),
            trainer=document.get("trainer") or {},
        )
    resolved = document.get("resolved") or {}
    planned = document.get("iterations")
    return RunConfigView(
        program="sweep",
        settings=document,
        sealed={key: value for key, value in document.items() if key != "provenance"},
        inputs=resolved.get("inputs") or {},
        return_range=resolved.get("normalizer"),
        return_range_source=resolved.get("normalizer_source"),
        label_ratios=document.get("label_ratios"),
        noise_stds=document.get("noise_stds"),
        planned_iterations=planned if isinstance(planned, int) else None,
        complete=None,
        trainer={},
    )


def _read_run_document(document: dict, program: str) -> RunConfigView:
    """``read_run_config`` of a document in ``run_document``'s layout, written by
    ``program``."""
    # A part that is not an object (a hand-edited file) reads as empty: the seal check then
    # names the change in one line, where .get on a string would raise deep inside.
    settings, resolved = (
        part if isinstance(part, dict) else {}
        for part in (document.get("config"), document.get("resolved"))
    )
    offline = program == "offline"
    planned = settings.get("iterations")
    return RunConfigView(
        program=program,
        settings=settings,
        sealed={key: value for key, value in document.items() if key not in RUN_UNSEALED},
        inputs=resolved.get("inputs") or {},
        return_range=resolved.get("return_range"),
        return_range_source=resolved.get("return_range_source"),
        label_ratios=[settings.get("label_ratio")] if offline else settings.get("label_ratios"),
        noise_stds=[settings.get("noise_std")] if offline else settings.get("noise_stds"),
        planned_iterations=_offline_planned(settings)
        if offline
        else (planned if isinstance(planned, int) else None),
        complete=document.get("complete") if offline else None,
        trainer=(resolved.get("trainer") or {}) if offline else {},
    )


def _offline_planned(settings: dict) -> int | None:
    """An offline run's iterations: its gradient steps over the steps per iteration."""
    steps, per_iteration = settings.get("gradient_steps"), settings.get("steps_per_iteration")
    if isinstance(steps, int) and isinstance(per_iteration, int) and per_iteration > 0:
        return steps // per_iteration
    return None


def run_scores(run_dir: Path, statistic: str = HEADLINE) -> tuple[str, dict[str, np.ndarray]]:
    """A sweep or offline run's task and each method label's scores float[seeds]
    (``statistic`` of the normalised evaluations; NaN for a seed that diverged), so the
    offline family's rows join the online methods' tables. RunReadError when the run has
    none to read."""

    run_dir = Path(run_dir)
    if output_owner(run_dir) not in RUN_PROGRAMS:
        raise RunReadError(
            f"{run_dir} holds no sweep or offline run (experiments.sweep or experiments.offline "
            "writes one)"
        )
    try:
        config = read_run_config(read_json(run_dir / "config.json", "run config")).settings
        env = config["env"]
    except (OSError, IntegrityError, KeyError, TypeError) as error:
        raise RunReadError(f"{run_dir}: no readable config.json ({error})") from None
    path = run_dir / "metrics.csv"
    if not path.exists():
        raise RunReadError(f"{run_dir}: no metrics.csv yet (the run has not finished a chunk)")
    return env, scores_of_metrics(path, config, run_progress_numbers(run_dir), statistic)


def scores_of_metrics(
    path: Path, config: dict, progress: tuple[int, int] | None, statistic: str = HEADLINE
) -> dict[str, np.ndarray]:
    """Each method label's scores float[seeds] (``statistic``, a key of ``STATISTICS``, of
    its normalised evaluations) in a sweep's metrics file (``metrics.csv``, or a run record's
    ``metrics.csv.gz``), checked whole against the run's ``config`` and ``progress``
    (iterations done and planned, when known). RunReadError for a damaged or cut-short
    file."""
    if statistic not in STATISTICS:
        raise RunReadError(f"statistic {statistic!r}: give one of {', '.join(STATISTICS)}")

    try:
        _check_whole(path, iterations_per_cell(path), progress, config)
        groups = read_evaluations(
            path, "normalized_return", evaluated_by="eval_return", group_by=("method", "setting")
        )
    except UNREADABLE as error:
        raise damaged(path, error) from None
    if not groups:
        raise RunReadError(f"{path}: no evaluated iteration")
    settings = {setting for _, setting in groups}
    scores = {}
    for (method, setting), (_, values) in groups.items():
        if np.isnan(values).all():
            raise RunReadError(
                f"{path}: {method} has no normalised return (the run knows no random and "
                "optimal returns: give --optimal-return to the sweep)"
            )
        label = method if len(settings) == 1 else f"{method} [{setting}]"
        scores[label] = seed_figures(values, statistic)
    return scores


UNREADABLE = (KeyError, ValueError, TypeError, EOFError, OSError, csv.Error)


def damaged(path: Path, error: Exception, kind: type = RunReadError) -> Exception:
    """The one-line error of a metrics file that does not parse (``UNREADABLE``)."""
    reason = f"no column {error}" if isinstance(error, KeyError) else str(error)
    return kind(f"{path} is damaged: not a metrics.csv as the sweep writes it ({reason})")


def _check_whole(path: Path, reached: dict, progress: tuple[int, int] | None, config: dict) -> None:
    """RunReadError when ``metrics.csv`` ends before the run did: a cell of the config
    missing (``config``'s methods x seeds, in every setting the file has), cells that stop at
    different iterations (a file cut within a cell), or all of them before the iteration its
    summary.json says the run reached (``progress``: iterations done and planned)."""
    if not reached:
        raise RunReadError(f"{path}: no rows")
    methods, seeds = config.get("methods"), config.get("seeds")
    if isinstance(methods, list) and isinstance(seeds, int):
        settings = {setting for _, setting, _ in reached}
        for method in methods:
            found = sum(1 for cell in reached if cell[0] == method)
            if found < seeds * len(settings):
                raise RunReadError(
                    f"{path} is cut short: it holds {found} of the {seeds * len(settings)} "
                    f"runs of {method} that config.json asks for"
                )
    lowest, highest = min(reached.values()), max(reached.values())
    if lowest != highest:
        short = next(cell for cell, last in reached.items() if last == lowest)
        raise RunReadError(
            f"{path} is cut short: {short[0]} seed {short[2]} ends at iteration {lowest}, "
            f"other cells at {highest}"
        )
    if progress is not None and highest < progress[0]:
        raise RunReadError(
            f"{path} is cut short: it ends at iteration {highest}, and summary.json says the "
            f"run reached {progress[0]}"
        )


def run_progress_numbers(run_dir: Path, document: dict | None = None) -> tuple[int, int] | None:
    """(iterations done, planned) from a run's summary.json (a sweep's), or for an offline
    run its config.json (``document`` where already read: its iterations are its gradient
    steps over the steps per iteration, done when it says it is complete); None where
    neither says."""
    if document is None and (Path(run_dir) / "config.json").is_file():
        try:
            document = read_json(Path(run_dir) / "config.json", "run config")
        except (OSError, IntegrityError):
            document = None
    view = read_run_config(document) if isinstance(document, dict) else None
    if view is not None and view.program == "offline":
        return _offline_progress(view)
    try:
        summary = read_json(Path(run_dir) / "summary.json", "run summary")
    except (OSError, IntegrityError):
        return None
    if not isinstance(summary, dict):
        return None
    planned = summary.get("iterations")
    done = planned if summary.get("complete") is True else summary.get("iterations_done")
    if isinstance(done, int) and isinstance(planned, int):
        return done, planned
    return None


def _offline_progress(view: RunConfigView) -> tuple[int, int] | None:
    """An offline run's (iterations done, planned), known once its config.json says it is
    complete (its summary keeps no progress; a run cut short has no summary to compare)."""
    planned = view.planned_iterations
    return (planned, planned) if planned is not None and view.complete is True else None


def run_progress(run_dir: Path) -> str | None:
    """None for a finished run (or one whose summary.json is missing: nothing says it is not),
    else how far it got ("200 of 500 iterations") from its summary.json, written each chunk."""
    try:
        summary = read_json(Path(run_dir) / "summary.json", "run summary")
    except FileNotFoundError:
        return None
    except (OSError, IntegrityError):
        return "unknown: its summary.json is unreadable"
    if not isinstance(summary, dict) or summary.get("complete") is not False:
        return None  # complete, or a run from before summaries said (nothing says it is not)
    done, planned = summary.get("iterations_done"), summary.get("iterations")
    if isinstance(done, int) and isinstance(planned, int):
        return f"{done:,} of {planned:,} iterations"
    return "unfinished"


class UntrustedRun(RunReadError):
    """A run folder that fails a check a program makes before it trusts it (the message
    names the file and the problem)."""


def sealed_part(document: dict) -> dict:
    """What a run's config seal covers: all but ``RUN_UNSEALED``; in the layouts before it,
    a sweep's config.json but its provenance (where it ran), an offline run's
    ``OFFLINE_SEALED`` parts (``read_run_config``)."""
    return read_run_config(document).sealed


def recorded_inputs(document: dict) -> dict:
    """The input files' records (``integrity.file_record``) a run's config.json holds."""
    return read_run_config(document).inputs


def verify_run(
    directory: Path,
    who: str,
    *,
    allow_unsealed: bool = False,
    check_inputs: bool = True,
) -> list[str]:
    """The one check every program makes before it trusts a sweep or offline run in
    ``directory``, each failure an ``UntrustedRun`` whose message starts with ``who`` (the
    flag and folder, e.g. ``"--adopt runs/a"``):

    - its config.json equals the seal written when the run began (``allow_unsealed``: a run
      without its seal goes on, its config unchecked, said in the notes returned);
    - its input files are those it began with (``check_inputs`` False: not looked at, for a
      reader of results such as compare, or a caller that checks them itself, as the sweep's
      resume with its ``--allow-changed-inputs``);
    - its metrics.csv is whole (every cell of the config, each to the iteration its
      summary.json says) and gives the final returns its summary.json states, seed by seed;
    - its policies (a finished sweep's) match their digests.

    Returns the notes of what was let through."""

    directory = Path(directory)
    if output_owner(directory) not in RUN_PROGRAMS:
        raise UntrustedRun(f"{who}: holds no sweep or offline run")
    document, notes = sealed_document(directory, who, allow_unsealed=allow_unsealed)
    inputs = changed_inputs(recorded_inputs(document)) if check_inputs else []
    if inputs:
        raise UntrustedRun(
            f"{who}: {'; '.join(inputs)}: its numbers come from other data than the files "
            "there now; restore them"
        )
    _check_metrics_agree_with_summary(directory, document, who)
    for policy in sorted((directory / "policies").glob("**/digests.json")):
        try:
            verify_manifest(policy.parent)
        except IntegrityError as error:
            raise UntrustedRun(f"{who}: {error}") from None
    return notes


UNSEALED_REMEDY = "restore the seal, or pass --allow-unsealed to go on unchecked"


def changed_inputs_refusal(changes: list[str], who: str, what: str, remedy: str) -> str:
    """The one line that refuses to go on with a ``what`` (a run, a plan) whose input files
    changed since it began (``changes``: ``integrity.changed_inputs``' lines), naming each
    file and the ``remedy``."""
    return (
        f"{who}: {'; '.join(changes)}. The rest of the {what} would train on other data than "
        f"its start: {remedy}"
    )


def sealed_document(
    directory: Path,
    who: str,
    *,
    name: str = "config.json",
    what: str = "run config",
    seal_name: str | None = None,
    part=sealed_part,
    allow_unsealed: bool = False,
    unsealed_remedy: str = UNSEALED_REMEDY,
) -> tuple[dict, list[str]]:
    """The one read of a run's record (a sweep's or offline run's config.json, train_rl's,
    the paper plan's paper.json, each written by ``integrity.write_sealed``): the document
    ``name`` (a ``what``, in messages) once ``part(document)`` equals its seal
    ``seal_name`` (default ``integrity.CONFIG_SEAL``), or, with ``allow_unsealed``, has none
    (a note says so), and the notes; else ``UntrustedRun`` starting with ``who`` and naming
    what differs."""

    seal_name = seal_name or CONFIG_SEAL
    try:
        document = read_json(directory / name, what)
        if not isinstance(document, dict):
            raise IntegrityError("not a JSON object")
        changes = sealed_differences(directory / seal_name, part(document))
    except FileNotFoundError:
        raise UntrustedRun(f"{who}: no {name} there") from None
    except (OSError, IntegrityError) as error:
        raise UntrustedRun(f"{who}: {error}") from None
    if changes is None and not allow_unsealed:
        raise UntrustedRun(
            f"{who}: its seal {seal_name} is missing (a copy without its dot-files, or a run "
            f"from before seals), so its {name} cannot be checked against what the run began "
            f"with; {unsealed_remedy}"
        )
    if changes:
        raise UntrustedRun(
            f"{who}: {name} was changed since the run began ({'; '.join(changes[:3])}"
            + (f"; and {len(changes) - 3} more" if len(changes) > 3 else "")
            + "): a run keeps what it began with; restore the file"
        )
    unsealed = [f"{who}: no seal, {name} unchecked (--allow-unsealed)"]
    return document, unsealed if changes is None else []


def run_return_range(document: dict) -> list[float] | None:
    """The (random, optimal) returns a run's config.json (or a record's config) sealed
    (``resolved.return_range``; in older layouts the sweep's ``resolved.normalizer``, the
    offline program's ``normalizer``); None when the run knew none (its normalised column
    is then empty)."""
    value = read_run_config(document).return_range
    if value is None:
        return None
    if (
        not isinstance(value, list)
        or len(value) != 2
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
        or not value[1] != value[0]
    ):
        raise RunReadError(f"its return range {value!r} is not two different returns")
    return [float(value[0]), float(value[1])]


# metrics.csv writes 6 significant digits: a written value is within 5e-6 of the value's
# magnitude of what was computed. Checks of written numbers allow twice that per value.
WRITTEN_RELATIVE = 1e-5


def _written_close(stated: float, recomputed: float, scale: float) -> bool:
    """Whether ``stated`` and ``recomputed`` (from values of magnitude up to ``scale``, each
    written to 6 significant digits) agree within that rounding."""
    return abs(stated - recomputed) <= WRITTEN_RELATIVE * max(abs(scale), 1e-300) + 1e-9


def read_scored_rows(path: Path, return_range: list[float] | None) -> dict:
    """Every evaluated row of a metrics file (a run's ``metrics.csv`` or a record's
    ``metrics.csv.gz``), checked: its ``normalized_return`` is its ``eval_return`` through
    ``return_range`` (empty when there is none, and in a row without an evaluation), to the
    file's rounding. Returns, per (method, setting) and seed, {iteration: eval_return}.
    RunReadError naming the file, method, seed and iteration of the first row that
    disagrees (a score edited, or the return range)."""

    rows: dict[tuple[str, str], dict[int, dict[int, float]]] = {}
    try:
        for row in metrics_rows(path):
            evaluated, score = row["eval_return"], row["normalized_return"]
            where = f"{path}: {row['method']} seed {row['seed']} iteration {row['iteration']}"
            if evaluated in ("", "nan"):
                if score not in ("", "nan"):
                    raise RunReadError(
                        f"{where} has a normalised return ({score}) but no evaluation: the "
                        "file was edited"
                    )
                continue
            value = float(evaluated)
            if return_range is None:
                if score not in ("", "nan"):
                    raise RunReadError(
                        f"{where}: normalised return {score} where the run knew no random "
                        "and optimal returns: the file was edited"
                    )
            elif math.isfinite(value):
                random_return, optimal_return = return_range
                span = optimal_return - random_return
                expected = (value - random_return) / span
                written = float(score) if score not in ("", "nan") else math.nan
                if not (
                    math.isfinite(written)
                    and _written_close(written, expected, abs(value / span) + abs(expected))
                ):
                    raise RunReadError(
                        f"{where}: normalised return {score or 'empty'} is not its evaluation "
                        f"{evaluated} through the run's return range ({expected:.6g}): one of "
                        "them was edited"
                    )
            group = rows.setdefault((row["method"], row["setting"]), {})
            group.setdefault(int(row["seed"]), {})[int(row["iteration"])] = value
    except RunReadError:
        raise
    except UNREADABLE as error:
        raise damaged(path, error) from None
    return rows


def _seed_figures(evaluations: dict[int, float]) -> dict[str, tuple[float, list[int], float]]:
    """A seed's figures from its evaluations {iteration: return}: per figure (final,
    late-average and training-average return), (value, the iterations it reads, the largest
    |return| among them),
    as ``report.summarize`` computes them (NaN evaluations left out of the averages)."""

    iterations = sorted(evaluations)
    late = iterations[len(iterations) - late_evaluations(len(iterations)) :]
    figures = {}
    for name, read in (("final_return", iterations[-1:]), ("late_average_return", late),
                       ("average_return", iterations)):  # fmt: skip
        values = np.array([evaluations[i] for i in read], np.float64)
        finite = values[np.isfinite(values)]
        mean = float(finite.mean()) if finite.size else math.nan
        figures[name] = (mean, read, float(np.abs(finite).max()) if finite.size else 0.0)
    return figures


# summary.json's per-seed figures that metrics.csv's evaluations give.
_FIGURE_FIELDS = tuple(
    f"{name}_{kind}" for name in ("final", "late_average", "average")
    for kind in ("return", "normalized_return")
)  # fmt: skip


def _check_summary_figures(
    rows: dict, summary: dict, return_range: list[float] | None, who: str
) -> None:
    """UntrustedRun unless each seed's final, late-average and training-average returns
    (raw and normalised) in ``summary.json`` are those its evaluations in metrics.csv give
    (``rows``, ``read_scored_rows``'), to the file's rounding; the message names the method,
    the seed, the figure and the iterations it reads. A seed the summary leaves null
    (diverged) is not compared."""
    settings = {setting for _, setting in rows}
    for (method, setting), seeds in rows.items():
        label = method if len(settings) == 1 else f"{method} [{setting}]"
        row = summary.get("methods", {}).get(label)
        if row is None:
            raise UntrustedRun(f"{who}: summary.json has no {label}, which metrics.csv has")
        for stated_seed in row.get("per_seed", []):
            seed = stated_seed.get("seed")
            if seed not in seeds:
                if all(stated_seed.get(field) is None for field in _FIGURE_FIELDS):
                    continue  # diverged before its first evaluation: nothing to compare
                raise UntrustedRun(
                    f"{who}: summary.json has {label} seed {seed}, which metrics.csv has not"
                )
            for name, (value, read, scale) in _seed_figures(seeds[seed]).items():
                span = (
                    f"iteration {read[0]}"
                    if len(read) == 1
                    else (f"iterations {read[0]}-{read[-1]}")
                )
                checks = [(name, value, scale)]
                if return_range is not None:
                    width = return_range[1] - return_range[0]
                    checks.append((
                        name.replace("_return", "_normalized_return"),
                        (value - return_range[0]) / width,
                        scale / abs(width),
                    ))  # fmt: skip
                for field, recomputed, magnitude in checks:
                    stated = stated_seed.get(field)
                    if stated is None or not math.isfinite(recomputed):
                        continue
                    number = isinstance(stated, (int, float)) and not isinstance(stated, bool)
                    if number and _written_close(stated, recomputed, magnitude):
                        continue
                    shown = f"{stated:.6g}" if number else repr(stated)
                    if field == "final_return":
                        raise UntrustedRun(
                            f"{who}: summary.json says {label} seed {seed} ended at {shown}, "
                            f"metrics.csv at {recomputed:.6g} ({span}): one of them was edited"
                        )
                    raise UntrustedRun(
                        f"{who}: summary.json gives {label} seed {seed} {field} {shown}, "
                        f"metrics.csv's evaluations ({span}) {recomputed:.6g}: one of them was "
                        "edited"
                    )


def _check_metrics_agree_with_summary(directory: Path, document: dict, who: str) -> None:
    """UntrustedRun unless metrics.csv is whole (every cell of the config, each to the
    iteration summary.json says), its every normalised return is its evaluation through the
    sealed return range (``read_scored_rows``), summary.json states the same return range, and
    each seed's final, late-average and training-average figures in summary.json are those
    metrics.csv gives (``_check_summary_figures``; 6 significant digits there; a diverged
    seed, null in the summary, is not compared). A summary behind metrics.csv (a stop
    between the two writes of a chunk) is not compared: the next chunk writes both again."""

    metrics, summary_path = directory / "metrics.csv", directory / "summary.json"
    if not metrics.exists():
        return  # no chunk finished yet, or outputs a resume writes again: nothing to agree
    progress = run_progress_numbers(directory, document)
    try:
        summary = read_json(summary_path, "run summary") if summary_path.exists() else None
        return_range = run_return_range(document)
    except (OSError, IntegrityError, RunReadError) as error:
        raise UntrustedRun(f"{who}: {error}") from None
    try:
        reached = iterations_per_cell(metrics)
        _check_whole(metrics, reached, progress, read_run_config(document).settings)
        rows = read_scored_rows(metrics, return_range)
    except UNREADABLE as error:
        raise damaged(metrics, error, UntrustedRun) from None
    except RunReadError as error:
        raise UntrustedRun(str(error)) from None
    done = max(reached.values()) if reached else None
    if not isinstance(summary, dict) or "methods" not in summary:
        return  # none, or cut to its progress fields: nothing stated to compare
    if progress is None or done != progress[0]:
        return
    states, stated = summary_return_range(summary)
    if states and (stated is not None if return_range is None else stated != return_range):
        raise UntrustedRun(
            f"{who}: summary.json's return range {stated!r} is not config.json's {return_range!r}: "
            "one of them was edited"
        )
    _check_summary_figures(rows, summary, return_range, who)
