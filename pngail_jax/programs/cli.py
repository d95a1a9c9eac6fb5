"""Command-line helpers shared by the programs in ``experiments``.

Every check exits through ``parser.error`` (status 2, the usage line, then the message) with a
message that names the flag, so a bad value never reaches the program as a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import numbers
import signal
from collections.abc import Sequence
from pathlib import Path

from pngail_jax.storage.integrity import IntegrityError, read_json
from pngail_jax.storage.outputs import output_owner, output_refusal


class HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Every flag's help ends with its default, unless the help already names it; epilogs and
    descriptions keep their line breaks."""

    def _get_help_string(self, action):
        help_text = action.help or ""
        if "default" in help_text or action.required:
            return help_text
        return super()._get_help_string(action)


class ArgumentParser(argparse.ArgumentParser):
    """A program's parser: usage lines that say ``python -m experiments.<program>``, every
    default in the help, and errors as one line (the program, the message and where the usage
    is) instead of the usage block followed by the message."""

    def __init__(self, program: str, description: str | None = None, **kwargs):
        super().__init__(
            prog=f"python -m experiments.{program}",
            description=description,
            formatter_class=kwargs.pop("formatter_class", HelpFormatter),
            **kwargs,
        )

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (usage: {self.prog} --help)\n")


def note_deprecated(argv: Sequence[str] | None, renamed: dict[str, str]) -> None:
    """Prints one note per old spelling in ``argv`` (``{old flag: new flag}``): the old flags
    keep working as aliases, and the note says the name to use."""
    import sys

    given = sys.argv[1:] if argv is None else argv
    for old, new in renamed.items():
        if any(item == old or item.startswith(f"{old}=") for item in given):
            print(f"note: {old} is deprecated; it is now {new}", file=sys.stderr)


def config_from(config_type, args: argparse.Namespace):
    """A job's config (a dataclass) of checked flags: each field from the flag of its name."""
    import dataclasses

    names = [field.name for field in dataclasses.fields(config_type)]
    return config_type(**{name: getattr(args, name) for name in names if hasattr(args, name)})


def current_spellings(argv: Sequence[str], renamed: dict[str, str]) -> list[str]:
    """``argv`` with each deprecated flag (``{old flag: new flag}``) spelled as it is now, so
    a recorded command line teaches the names to use."""
    spelled = []
    for item in argv:
        flag, equals, value = item.partition("=")
        spelled.append(renamed.get(flag, flag) + equals + value if flag in renamed else item)
    return spelled


def _items(parser: argparse.ArgumentParser, prefix: str, text: str, what: str) -> list[str]:
    """The stripped comma-separated items of a flag's value; an empty one (``"a,,b"``,
    ``"a,"``, ``""``) exits with ``prefix`` (the flag) leading the message."""
    items = [item.strip() for item in str(text).split(",")]
    if not all(items):
        parser.error(f"{prefix}empty item in {text!r} (expected comma-separated {what})")
    return items


def known_names(
    parser: argparse.ArgumentParser,
    text: str,
    known: Sequence[str],
    kind: str,
    flag: str | None = None,
) -> list[str]:
    """The comma-separated names in ``text`` (a flag's value), in order; exits through
    ``parser.error`` naming the unknown ones (and what is available) when any name is not in
    ``known``, and on an empty item or a repeated name. ``kind`` names one item, e.g.
    ``"method"``; ``flag`` (e.g. ``"--methods"``) starts each message when given."""
    prefix = f"{flag}: " if flag else ""
    names = _items(parser, prefix, text, f"{kind} names")
    unknown = [name for name in names if name not in known]
    if unknown:
        parser.error(f"{prefix}unknown {kind}(s) {unknown}; available: {', '.join(known)}")
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        parser.error(f"{prefix}{kind}(s) {repeated} given more than once")
    return names


def comma_floats(parser: argparse.ArgumentParser, flag: str, text: str | None):
    """The comma-separated finite numbers of a flag's value as a tuple of floats (None when
    not given); exits through ``parser.error`` naming ``flag`` on an empty item, an item that
    is not a number, or a NaN or infinity (``"nan"``, ``"inf"``, ``"1e999"``)."""
    if text is None:
        return None
    values = []
    for item in _items(parser, f"{flag}: ", text, "numbers"):
        try:
            value = float(item)
        except ValueError:
            parser.error(f"{flag} must be comma-separated numbers, got {text!r}")
        if not math.isfinite(value):
            parser.error(f"{flag} values must be finite numbers, got {item!r}")
        values.append(value)
    return tuple(values)


ENV_HELP = (
    "a built-in (Pendulum-v1; gymnasium's Hopper-v4, HalfCheetah-v4, Walker2d-v4, Swimmer-v4, "
    "Ant-v4; Brax's Ant, HalfCheetah, Hopper, Walker2d and the MJX Swimmer), a registered "
    "name, or package.module:factory (docs/environments.md)"
)


def check_env(parser: argparse.ArgumentParser, name: str, flag: str = "--env") -> str:
    """``name`` when ``pngail_jax.envs.make`` knows it; else exits through ``parser.error``
    naming ``flag`` and what is available."""
    from pngail_jax import envs

    try:
        envs.check_name(name)
    except (ValueError, TypeError) as error:  # TypeError: a relative module name (".x:f")
        parser.error(f"{flag}: {error}")
    return name


def _flag(name: str) -> str:
    return f"--{name.replace('_', '-')}"


def check_positive(parser: argparse.ArgumentParser, args, names) -> None:
    """Exits through ``parser.error`` naming the first flag (``args`` attribute) whose value
    is not a positive integer (below 1, or not an integer); flags left at None (not given,
    no default) are skipped."""
    for name in names:
        value = getattr(args, name)
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            parser.error(f"{_flag(name)} must be a positive integer, got {value!r}")


def check_finite(parser: argparse.ArgumentParser, args, names) -> None:
    """Exits through ``parser.error`` naming the first flag (``args`` attribute) whose number
    is NaN or infinite (``type=float`` accepts ``nan``, ``inf`` and ``1e999``); flags left at
    None are skipped."""
    for name in names:
        value = getattr(args, name)
        if value is None:
            continue
        # Not a number: argparse turns the value "--" into [] (it drops "--" from values).
        if not isinstance(value, numbers.Real) or not math.isfinite(value):
            parser.error(f"{_flag(name)} must be a finite number, got {value!r}")


# -- the output contract (pngail_jax.storage.outputs) ----------------------------------------------


def claim_output(
    parser: argparse.ArgumentParser,
    directory: Path,
    program: str,
    overwrite: bool = False,
    flag: str = "--out",
) -> None:
    """Exits through ``parser.error`` with ``output_refusal``'s reason, if there is one."""
    refusal = output_refusal(directory, program, overwrite, flag)
    if refusal:
        parser.error(refusal)


# What --resume DIR takes besides itself (train_rl's and make_demos'): the run's config.json
# holds every other flag.
RESUME_FLAGS = ("--resume", "--compile-cache", "--no-compile-cache")


def resumed_args(
    parser: argparse.ArgumentParser,
    given: argparse.Namespace,
    argv: Sequence[str],
    *,
    program: str,
    finished: str,
    job: str,
    check,
    read_argv=lambda document: document["config"]["argv"],
) -> argparse.Namespace:
    """The flags of the run of ``program`` in ``given.resume`` (``read_argv`` of its
    config.json), parsed and checked again (``check(parser, args)``), with ``out``, ``resume``
    and ``argv`` (the stored flags) set and this command's compilation-cache flags: what
    ``--resume DIR`` runs. Exits through ``parser.error`` when ``argv`` has any other flag
    but ``RESUME_FLAGS``, the directory holds no run of ``program`` or a finished one (its
    ``finished`` file written), or no flags (a run begun from Python: ``job``, the function
    it began with, resumes it)."""
    directory = given.resume
    if any(a.split("=")[0] not in RESUME_FLAGS for a in argv if a.startswith("--")):
        parser.error("--resume DIR takes no other flags: the run's config.json has them")
    if output_owner(directory) != program:
        parser.error(f"--resume {directory} holds no run of experiments.{program}")
    if (directory / finished).exists():
        parser.error(f"--resume {directory}: the run is complete (its {finished} is written)")
    try:
        stored = read_argv(read_json(directory / "config.json", f"{program} run config"))
    except (OSError, IntegrityError, KeyError, TypeError, AttributeError) as error:
        parser.error(f"--resume {directory}: no flags to resume with ({error})")
    if not isinstance(stored, list):  # begun from Python, with no flags
        parser.error(
            f"--resume {directory}: no flags to resume with (a run begun from Python: "
            f"resume it with {job}(..., resume=True))"
        )
    args = parser.parse_args(stored)
    check(parser, args)
    args.out, args.resume, args.argv = directory, directory, stored
    args.compile_cache, args.no_compile_cache = given.compile_cache, given.no_compile_cache
    return args


def text_argument(text: str) -> str:
    """An argparse ``type`` for a value that must not be empty (a path, a dataset id)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("must name a path, got ''")
    return text


def path_argument(text: str) -> Path:
    """An argparse ``type`` for paths: an empty string is refused (``Path("")`` would mean
    the current directory)."""
    return Path(text_argument(text))


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)  # Ctrl-C, and kill's or a scheduler's


@contextlib.contextmanager
def signals_stop_at_a_checkpoint():
    """Within it, SIGTERM (``kill``'s default, and what a batch scheduler sends at a job's
    time limit) stops the program as Ctrl-C does, and both let a chunk that has begun end
    and be saved first (``jobs.chunks.stop_after_this_chunk``; a second signal stops at once).
    Stopped, the run lock is released, a plan's time is recorded and the program says how to
    ``--resume``; without it SIGTERM killed the process with its lock left behind (another
    host then refuses to take it over), and either signal, which reaches Python only when a
    compiled chunk returns, discarded that finished chunk. The previous handlers are restored
    on leaving; outside the main thread (where Python cannot set one) it does nothing."""
    import sys
    import threading

    from pngail_jax.jobs.chunks import stop_after_this_chunk

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        name = signal.Signals(signum).name
        if not stop_after_this_chunk():
            raise KeyboardInterrupt(name)
        print(f"\n{name}: the run stops once this chunk is saved ({name} again: at once)",
              file=sys.stderr, flush=True)  # fmt: skip

    previous = {number: signal.signal(number, interrupt) for number in STOP_SIGNALS}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def interrupted(out: Path, finished: str = "chunks") -> str:
    """The one line a program ends with on Ctrl-C (or a scheduler's SIGTERM): what it kept in
    ``out`` (its ``finished`` pieces: chunks, blocks) and how to continue, or that nothing
    was written when the run had not begun."""
    if (Path(out) / "config.json").exists():
        return (
            f"\ninterrupted: finished {finished} are kept; --resume {out} continues from the "
            "last one"
        )
    return "\ninterrupted before the run began: nothing was written"


def invoked_as(program: str) -> list[str]:
    """The words that start ``program`` as this process was started: the installed command
    (``pngail-sweep``) when it runs as one, else ``python -m experiments.<program>`` (a
    checkout's entry point), so a recorded command line can be run again as it stands."""
    import sys

    name = Path(sys.argv[0]).name
    return [name] if name.startswith("pngail-") else ["python", "-m", f"experiments.{program}"]


def add_allow_unsealed(add, what: str) -> None:
    """``--allow-unsealed`` through ``add`` (a parser's or group's ``add_argument``): go on
    with ``what`` although its config seal is missing, its config unchecked and said so
    (``runs.verify_run``); every program that reads an earlier run offers it alike."""
    add(
        "--allow-unsealed",
        action="store_true",
        help=f"{what} without its config seal (a copy made without its dot-files, or a run "
        "from before seals), its config.json unchecked, which the output says (default: "
        "refuse)",
    )


def check_json_output(parser, path: Path | None, overwrite: bool) -> None:
    """A ``--json FILE`` a program writes: not a folder, and not a file already there unless
    ``overwrite`` (``--overwrite``); else ``parser.error`` in one line."""
    if path is None:
        return
    if path.is_dir():
        parser.error(f"--json {path} is a directory; give the path of a file to write")
    if path.exists() and not overwrite:
        parser.error(f"--json {path} exists: choose another file, or pass --overwrite")


def check_read_run(parser, directory: Path, allow_unsealed: bool = False) -> None:
    """A program that reads results from a run folder or a record trusts it only as every
    other does: a record (``record.json`` beside ``metrics.csv.gz``) once
    ``run_records.check_record`` passes, a run once ``runs.verify_run`` does (its input files
    not looked at: results are read, not data); else ``parser.error`` in one line. The notes
    of what ``allow_unsealed`` let through are printed."""
    from pngail_jax.analysis.run_records import METRICS_FILE, RECORD_FILE, RecordError, check_record
    from pngail_jax.analysis.runs import UntrustedRun, verify_run

    directory = Path(directory)
    try:
        if (directory / RECORD_FILE).is_file() and (directory / METRICS_FILE).is_file():
            check_record(directory)
            return
        for note in verify_run(directory, str(directory), allow_unsealed=allow_unsealed,
                               check_inputs=False):  # fmt: skip
            print(f"note: {note}")
    except (RecordError, UntrustedRun) as error:
        parser.error(str(error))


def add_compile_cache_flags(parser) -> None:
    """``--compile-cache DIR`` and ``--no-compile-cache``; ``use_compile_cache`` applies them."""
    from pngail_jax.storage.compilation import CACHE_ENVIRONMENT_VARIABLE

    parser.add_argument(
        "--compile-cache",
        type=Path,
        metavar="DIR",
        help=f"persistent compilation cache (default ${CACHE_ENVIRONMENT_VARIABLE} or "
        "~/.cache/pngail-jax/xla): a repeated command does not compile again",
    )
    parser.add_argument(
        "--no-compile-cache",
        action="store_true",
        help="compile every program afresh (nothing read from or written to the cache) "
        "(default: off)",
    )


def use_compile_cache(args) -> Path | None:
    """Applies the flags of ``add_compile_cache_flags``: the cache directory in use, or None."""
    from pngail_jax.storage.compilation import enable_compilation_cache

    if args.no_compile_cache:
        return None
    try:
        return enable_compilation_cache(args.compile_cache)
    except (ValueError, OSError) as error:
        raise SystemExit(f"--compile-cache: {error}") from None
