"""Re-run a record's command on this machine and check the result against the record.

    python -m experiments.record --reproduce check-pendulum           # minutes on 2 CPU cores
    python -m experiments.record --reproduce pendulum-10seeds --out runs/mine

The record's stored command (``record.json``'s ``command``: the older forms ``python -m
offline`` and ``pngail-<program>`` read as ``python -m experiments.<program>``) runs with its
``--out`` replaced by this re-run's folder (default ``runs/reproduce-<NAME>``) and its
``--overwrite`` dropped: a new or empty folder gets a new run; a folder holding a run of the
same config (this re-run, cut short) is continued with ``--resume``, or only checked when it
is finished; anything else there is refused (``storage.outputs``), never written over. The
finished run is then checked as ``experiments.compare --expected`` checks a run: per method,
whether the IQM of its seeds' headline scores lies inside the record's 95% bootstrap interval
of its IQM over seeds (``run_records.expected_rows``), with both sides' machine and commit,
and whether the seeds are the record's to the last bit (what the same CPU model, libraries,
``XLA_FLAGS`` and commit give: docs/sweep.md, "What is reproducible"). It returns True when
every method agrees; the record program exits 1 otherwise.
"""

from __future__ import annotations

import math
import re
import subprocess
import sys
import time
from pathlib import Path

from pngail_jax.analysis import compare, run_records
from pngail_jax.analysis.report import HEADLINE
from pngail_jax.analysis.runs import (
    RUN_PROGRAMS,
    STATISTICS,
    read_run_config,
    run_progress_numbers,
)
from pngail_jax.storage.integrity import IntegrityError, read_json
from pngail_jax.storage.outputs import output_owner, output_refusal

# The flags a re-run sets itself: where it writes, and never over another run.
_OWN_FLAGS = ("--out", "--resume")
_DROPPED_FLAGS = ("--overwrite",)
# What decides whether two runs give the same bits (docs/sweep.md, "What is reproducible").
_SAME_PROGRAM_KEYS = ("cpu_model", "libraries", "xla_flags", "platform", "device_count")
_CODE = ("pngail_jax", "experiments", "examples", "pyproject.toml")  # what makes the numbers
_NAME = re.compile(r"[\w-][\w.-]*")  # a record's folder name, as run_records.check_name takes
_PROGRAM = re.compile(r"[a-z][a-z_]*")  # a module of pngail_jax.programs


def default_out(name: str) -> Path:
    """Where a re-run of the record ``name`` goes unless told: ``runs/reproduce-<name>``."""
    return Path("runs") / f"reproduce-{name}"


def record_folder(name: str, records: Path) -> Path:
    """``records/<name>``, or RecordError in one line listing the records there are."""
    folder = Path(records) / name
    if _NAME.fullmatch(name) and (folder / run_records.RECORD_FILE).is_file():
        return folder
    known = sorted(path.parent.name for path in Path(records).glob(f"*/{run_records.METRICS_FILE}"))
    listing = ", ".join(known) if known else "none"
    raise run_records.RecordError(
        f"no record {name!r} in {records}/ (the records of runs there: {listing})"
    )


def stored_command(record: dict) -> tuple[str, list[str]]:
    """(program, its arguments) of the record's command as it runs today: ``python -m
    experiments.<program> ARGS`` as stored, and the older forms read as that (``python -m
    offline ARGS``, format 2's slip; ``pngail-<program> ARGS``, an installed command).
    RecordError for a record that keeps no command of a program of this package."""
    command = record.get("command")
    name = record.get("name")
    if not (isinstance(command, list) and command and all(isinstance(w, str) for w in command)):
        raise run_records.RecordError(f"the record {name} keeps no command to run")
    first = Path(command[0]).name
    if first.startswith("pngail-"):
        program, argv = first.removeprefix("pngail-").replace("-", "_"), command[1:]
    elif first.startswith("python") and len(command) >= 3 and command[1] == "-m":
        program, argv = command[2].removeprefix("experiments."), command[3:]
    else:
        program, argv = "", []
    if not (_PROGRAM.fullmatch(program) and (Path(__file__).parent / f"{program}.py").is_file()):
        shown = " ".join(command[:3])
        raise run_records.RecordError(
            f"the record {name}'s command ({shown} ...) runs no program of this package"
        )
    return program, list(argv)


def rerun_arguments(argv: list[str], out: Path) -> list[str]:
    """``argv`` writing into ``out``: its ``--out`` and ``--resume`` (either form) and
    ``--overwrite`` taken out, ``--out OUT`` added."""
    kept, skip = [], False
    for word in argv:
        if skip:
            skip = False
            continue
        flag = word.split("=", 1)[0]
        if flag in _OWN_FLAGS:
            skip = "=" not in word
            continue
        if flag not in _DROPPED_FLAGS:
            kept.append(word)
    return [*kept, "--out", str(out)]


def _same_run(out: Path, record: dict) -> list[str]:
    """The config fields in which the run in ``out`` differs from the record's (those that
    change the numbers, ``run_records.config_differences``); RecordError when it has no
    readable config."""
    from pngail_jax.config.run_config import RunConfig  # JAX's import only when it runs
    from pngail_jax.jobs.offline_config import offline_defaults

    try:
        config = read_json(out / "config.json", "run config")
    except (OSError, IntegrityError) as error:
        raise run_records.RecordError(
            f"--out {out} holds a run whose config.json cannot be read ({error}): choose "
            "another --out"
        ) from None
    return run_records.config_differences(config, record, RunConfig().to_dict(), offline_defaults())


def _former_defaults(record: dict, program: str) -> list[str]:
    """The flags that pin what an offline record ran with where a default changed since
    (``jobs.offline_config.former_default_flags``); none for a sweep's."""
    if program != "offline":
        return []
    from pngail_jax.jobs.offline_config import former_default_flags

    return former_default_flags(dict(read_run_config(record["config"]).settings))


def plan(record: dict, program: str, argv: list[str], out: Path) -> tuple[str, list[str]]:
    """What the re-run does in ``out``: ("run", the record's arguments into ``out``) for a new
    or empty folder, ("resume", ``--resume OUT``) for this re-run cut short (a run of the
    record's program and config), ("check", []) for it finished. RecordError, naming what is
    there, for anything else: a re-run writes over nothing it did not make."""
    out = Path(out)
    refusal = output_refusal(out, program)
    if refusal is None:
        return "run", rerun_arguments(argv, out) + _former_defaults(record, program)
    if output_owner(out) != program:
        raise run_records.RecordError(refusal)  # another program's run, or files it did not make
    if not (out / "config.json").is_file():
        raise run_records.RecordError(
            f"--out {out} holds a run of experiments.{program} without its config.json: choose "
            "another --out"
        )
    differences = _same_run(out, record)
    if differences:
        raise run_records.RecordError(
            f"--out {out} holds another run of experiments.{program} (its config differs from "
            f"the record {record['name']}'s in: {', '.join(differences)}): choose another --out"
        )
    progress = run_progress_numbers(out)
    if progress is not None and progress[0] == progress[1]:
        return "check", []
    return "resume", ["--resume", str(out)]


def run_program(program: str, argv: list[str]) -> int:
    """``python -m experiments.<program> ARGV`` in this checkout, as the record's command runs
    (its relative paths are the checkout's); its exit status. On Ctrl-C the program, which
    had the signal too, is waited for while it stops at its checkpoint, never killed."""
    with subprocess.Popen([sys.executable, "-m", f"experiments.{program}", *argv]) as child:
        try:
            return child.wait()
        except KeyboardInterrupt:
            return child.wait()


def reproduce(name: str, records: Path = Path("records"), out: Path | None = None,
              run=run_program) -> bool:  # fmt: skip
    """Runs the record ``name``'s command into ``out`` (default ``runs/reproduce-<name>``),
    continuing it when it was cut short, then prints per method whether the re-run agrees
    with the record; True when every method does. RecordError in one line for an unknown
    record, a folder in the way, or a run that did not finish. ``run(program, argv)`` runs a
    program (tests pass one that runs it in their process)."""
    folder = record_folder(name, records)
    if not (folder / run_records.METRICS_FILE).is_file():  # a settings comparison's record
        try:
            program = read_json(folder / run_records.RECORD_FILE, "record").get("program")
        except (OSError, IntegrityError, AttributeError) as error:
            raise run_records.RecordError(f"{folder}: unreadable record ({error})") from None
        raise run_records.RecordError(
            f"the record {name} is a comparison of {program}; --reproduce checks the records "
            f"of {' and '.join(f'experiments.{p}' for p in RUN_PROGRAMS)} runs"
        )
    record = run_records.check_record(folder)
    program, argv = stored_command(record)
    if program not in RUN_PROGRAMS:  # e.g. a paper grid's record, which stores the plan's command
        raise run_records.RecordError(
            f"the record {name} stores a command of experiments.{program}; --reproduce re-runs "
            f"the commands of {' and '.join(f'experiments.{p}' for p in RUN_PROGRAMS)} runs"
        )
    if not Path(f"experiments/{program}.py").is_file():
        raise run_records.RecordError(
            f"run --reproduce from the root of a pngail-jax checkout: the record's command is "
            f"python -m experiments.{program}, and its paths are the checkout's"
        )
    out = default_out(name) if out is None else Path(out)
    action, arguments = plan(record, program, argv, out)
    started = time.monotonic()
    if action == "check":
        print(f"{out} holds the finished re-run of {name}: checking it")
    else:
        print(f"{'continuing' if action == 'resume' else 'running'} the record {name}'s command: "
              f"python -m experiments.{program} {' '.join(arguments)}", flush=True)  # fmt: skip
        status = run(program, arguments)
        if status != 0:
            raise run_records.RecordError(
                f"the re-run stopped (exit status {status}; its reason above): the same "
                f"command continues it in {out}"
            )
    lines, agreed = agreement(record, out)
    if action != "check":
        lines.insert(0, f"re-run took {_minutes(time.monotonic() - started)} here; the record's "
                     f"training {_minutes(record.get('training_seconds'))}")  # fmt: skip
    print("\n".join(lines))
    return agreed


def _minutes(seconds) -> str:
    if not isinstance(seconds, (int, float)) or not math.isfinite(seconds):
        return "not recorded"
    return f"{int(seconds // 60)} min {int(seconds % 60)} s"


def agreement(record: dict, out: Path, statistic: str = HEADLINE) -> tuple[list[str], bool]:
    """The lines that say per method whether the run in ``out`` agrees with ``record``, with
    both sides' machine and commit and the tolerance; and whether every method agrees. The
    tolerance is what the project measured a re-run to give (docs/sweep.md, "What is
    reproducible"): the record's code on its kind of machine (``bit_for_bit``) gives every
    seed to the last bit; anything else is another draw, held to ``compare --expected``'s
    test, the IQM of its seeds inside the record's 95% bootstrap interval under
    ``statistic``. A method whose seeds are all the record's agrees either way."""
    try:
        scores = compare.load_scores([out], statistic)
    except compare.CompareError as error:
        raise run_records.RecordError(str(error)) from None
    notes = run_records.check_comparable([out], record)
    rows = run_records.expected_rows(scores, record)
    try:
        document = read_json(out / "config.json", "run config")
    except (OSError, IntegrityError) as error:
        raise run_records.RecordError(f"{out}: its config.json cannot be read ({error})") from None
    mine = document.get("provenance") or {}
    resumed = document.get("resumed_provenance")  # an offline run's last resume, if any
    exact = bit_for_bit(record, mine) and (resumed is None or bit_for_bit(record, resumed))
    lines = [
        f"Against the record {record['name']} ({scores.tasks[0]}):",
        f"  record:   {_machine(record.get('machine') or {}, record.get('commit'))}",
        f"  this run: {_machine(mine, mine.get('git_commit'))}",
        *(f"  note: {note}" for note in notes),
        "  agrees when: " + _tolerance(exact, statistic),
    ]
    recorded, agreeing = record[run_records.statistic_key(statistic)], 0
    for row in rows:
        seeds = scores.values.get(row["method"], {}).get(scores.tasks[0])
        identical = seeds is not None and _as_listed(seeds) == recorded[row["method"]]
        agrees = identical or (not exact and row["verdict"] == "within")
        agreeing += agrees
        lines.append("  " + _method_line(row, identical, agrees))
    agreed = agreeing == len(rows)
    lines.append(f"{agreeing} of {len(rows)} methods agree with the record {record['name']}"
                 + ("" if agreed else ": not reproduced"))  # fmt: skip
    return lines, agreed


def _as_listed(values) -> list[float | None]:
    """Scores as a record lists them (None for a seed without a finite score)."""
    return [float(v) if math.isfinite(v) else None for v in values]


def bit_for_bit(record: dict, provenance: dict) -> bool:
    """Whether the run of ``provenance`` should give the record's numbers to the last bit:
    the same code (``same_code`` of the two commits) on the same CPU model, libraries,
    XLA_FLAGS, platform and number of devices (docs/sweep.md, "What is reproducible")."""
    machine = record.get("machine") or {}
    return all(
        machine.get(key) is not None and provenance.get(key) == machine.get(key)
        for key in _SAME_PROGRAM_KEYS
    ) and same_code(record.get("commit"), provenance.get("git_commit"))


def same_code(first, second) -> bool:
    """Whether two commits hold the same code: equal, or no file of the package, the entry
    points or the examples differs between them (``git diff``, run in this checkout). False
    for an unknown commit or one with uncommitted changes (``+dirty``)."""
    if not (isinstance(first, str) and isinstance(second, str)) or "+" in first + second:
        return False
    if first == second:
        return True
    try:
        differ = subprocess.run(
            ["git", "diff", "--quiet", first, second, "--", *_CODE], capture_output=True, timeout=30
        )
    except (OSError, subprocess.SubprocessError):
        return False
    return differ.returncode == 0


def _tolerance(exact: bool, statistic: str) -> str:
    if exact:
        return ("every seed is the record's to the last bit: this run has the record's code, "
                "CPU model, libraries, XLA_FLAGS and devices (docs/sweep.md, \"What is "
                "reproducible\")")  # fmt: skip
    return (f"the IQM of the re-run's seeds lies inside the record's 95% bootstrap interval "
            f"of its IQM over seeds (2,000 resamples; compare --expected's test), a seed "
            f"scored by its {STATISTICS[statistic]} ({statistic}); another machine or code than "
            f"the record's makes each seed another draw, so outside is a difference to look "
            f"at, not proof of one (docs/sweep.md, \"What is reproducible\")")  # fmt: skip


def _short(commit) -> str:
    """A commit as the output shows it: 10 digits, and whether the tree had changes."""
    if not isinstance(commit, str):
        return "not recorded"
    return commit[:10] + ("+dirty" if commit.endswith("+dirty") else "")


def _machine(machine: dict, commit) -> str:
    libraries = machine.get("libraries") or {}
    jax = f"jax {libraries.get('jax')}" if libraries.get("jax") else "jax not recorded"
    flags = machine.get("xla_flags")
    return (
        f"commit {_short(commit)}, {machine.get('cpu_model') or 'CPU not recorded'}, "
        f"{machine.get('platform') or '?'} x {machine.get('device_count') or '?'}, {jax}, "
        f"XLA_FLAGS {flags!r}"
    )


def _method_line(row: dict, identical: bool, agrees: bool) -> str:
    low, high = row["reference_ci95"]
    interval = f"[{low:.3f}, {high:.3f}]"
    head = f"{row['method']:<16} {'agrees ' if agrees else 'DIFFERS'}"
    if "your_iqm" not in row:
        return f"{head}  not in the re-run; the record's IQM {interval}"
    if not math.isfinite(row["your_iqm"]):
        return f"{head}  no finite return; the record's IQM {interval}"
    verdict = row["verdict"]
    where = "inside" if verdict == "within" else f"{verdict} by {row['outside_by']:.3f}"
    same = "every seed identical to the record's" if identical else "seeds differ from the record's"
    return (
        f"{head}  IQM {row['your_iqm']:.3f} ({row['your_seeds']} seeds), {where} the record's "
        f"{row['reference_iqm']:.3f} {interval} ({row['reference_seeds']} seeds); {same}"
    )
