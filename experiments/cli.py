"""Command-line helpers shared by the programs in ``experiments``.

Every check exits through ``parser.error`` (status 2, the usage line, then the message) with a
message that names the flag, so a bad value never reaches the program as a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import numbers
from collections.abc import Sequence
from pathlib import Path


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


@contextlib.contextmanager
def ticking(label: str, every: float | None = None, stream=None):
    """Shows the elapsed time of a long step that prints nothing itself (a first compile takes
    minutes on a CPU): on a terminal, ``label ... 42 s`` rewritten in place each second;
    elsewhere (a log file), a line every ``every`` seconds (default 30)."""
    import sys
    import threading
    import time

    stream = stream or sys.stdout
    live = stream.isatty()
    interval = every if every is not None else (1.0 if live else 30.0)
    start, done = time.perf_counter(), threading.Event()

    def tick():
        while not done.wait(interval):
            elapsed = time.perf_counter() - start
            text = f"{label} ... {elapsed:.0f} s"
            stream.write(f"\r{text}" if live else f"{text}\n")
            stream.flush()

    print(f"{label} ...", file=stream, end="" if live else "\n", flush=True)
    thread = threading.Thread(target=tick, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()
        if live:
            stream.write("\n")


def note_deprecated(argv: Sequence[str] | None, renamed: dict[str, str]) -> None:
    """Prints one note per old spelling in ``argv`` (``{old flag: new flag}``): the old flags
    keep working as aliases, and the note says the name to use."""
    import sys

    given = sys.argv[1:] if argv is None else argv
    for old, new in renamed.items():
        if any(item == old or item.startswith(f"{old}=") for item in given):
            print(f"note: {old} is deprecated; it is now {new}", file=sys.stderr)


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


# -- the output contract -------------------------------------------------------------------
#
# An output directory is new, or empty, or a run of the same program (marked so when it was
# created) that the user asked to resume or to replace with --overwrite. Anything else is
# refused before any computation, naming what is in the way.

MARKER = ".pngail-run.json"
LOCK = ".pngail-run.lock"  # held while a process writes the run (run_lock)
# Runs made before the marker existed are known by files of their program's own (the most
# specific first: train_rl writes a config.json too, without the sweep's "resolved").
LEGACY_MARKS = {
    "paper": ("paper.json",),
    "compare_settings": ("comparison.json",),
    "make_demos": ("demos.npz", "normalizer.json"),  # normalizer.json: one cut short
    "train_rl": ("policy.json",),
}
RESUMABLE = {"sweep", "paper"}


def output_owner(directory: Path) -> str | None:
    """The program whose run ``directory`` holds (its marker, else a legacy file), or None."""
    import json

    directory = Path(directory)
    marker = directory / MARKER
    if marker.is_file():
        try:
            return str(json.loads(marker.read_text())["program"])
        except (OSError, ValueError, KeyError, TypeError):
            return None
    for program, names in LEGACY_MARKS.items():
        if any((directory / name).exists() for name in names):
            return program
    config = directory / "config.json"
    if config.is_file():  # the sweep's has what it resolved; train_rl's (cut short) has not
        try:
            document = json.loads(config.read_text())
        except (OSError, ValueError):
            return None
        if isinstance(document, dict):
            return "sweep" if "resolved" in document else "train_rl" if "trpo" in document else None
    return None


def output_refusal(
    directory: Path, program: str, overwrite: bool = False, flag: str = "--out"
) -> str | None:
    """Why ``directory`` may not receive ``program``'s outputs, or None when it may: it is new
    or empty (its own marker alone, left by a start that failed, counts as empty), or holds a
    run of ``program`` and ``overwrite`` is set. The run lock is not content. Reads only."""
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        return f"{flag} {directory} is a file, not a directory"
    import os

    for parent in directory.parents:
        if parent.exists():
            if not parent.is_dir():
                return f"{flag} {directory}: {parent} is a file, not a directory"
            break
    nearest = directory if directory.exists() else next(p for p in directory.parents if p.exists())
    if not os.access(nearest, os.W_OK | os.X_OK):  # e.g. a read-only disk: say so now
        return f"{flag} {directory}: {nearest} is not writable (read-only disk or permissions)"
    if not directory.exists():
        return None
    contents = sorted(path.name for path in directory.iterdir() if path.name != LOCK)
    owner = output_owner(directory)
    if not contents or (contents == [MARKER] and owner == program):
        return None
    if owner == program:
        if overwrite:
            return None
        resume = f"--resume {directory} to continue it, " if program in RESUMABLE else ""
        return (
            f"{flag} {directory} already holds a run of experiments.{program}: {resume}pass "
            f"--overwrite to replace it, or choose another {flag}"
        )
    shown = ", ".join(contents[:5])
    shown += f" and {len(contents) - 5} more" if len(contents) > 5 else ""
    what = f"a run of experiments.{owner}" if owner else f"files it did not make ({shown})"
    return (
        f"{flag} {directory} is not empty: it holds {what}; experiments.{program} writes only "
        f"into a new or empty directory, or over its own run: choose another {flag}"
    )


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


def prepare_output(directory: Path, program: str, overwrite: bool = False) -> None:
    """Creates ``directory`` and marks it as ``program``'s run; with ``overwrite``, first
    empties it, which ``claim_output`` allowed only for a run of ``program``."""
    import json
    import shutil

    from pngail_jax.integrity import atomic_write_text

    directory = Path(directory)
    if overwrite and directory.exists() and output_owner(directory) == program:
        for path in directory.iterdir():
            if path.name == LOCK:  # the lock of the process doing this
                continue
            shutil.rmtree(path) if path.is_dir() and not path.is_symlink() else path.unlink()
    directory.mkdir(parents=True, exist_ok=True)
    if not (directory / MARKER).exists():
        atomic_write_text(directory / MARKER, json.dumps({"program": program}) + "\n")


class RunLocked(Exception):
    """Another live process holds the run's lock (the message names it)."""


def _alive(pid: int) -> bool:
    import os

    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


@contextlib.contextmanager
def run_lock(directory: Path, program: str):
    """Holds ``directory``'s run lock while a program writes there: a second process on the
    same run is refused (``RunLocked``, naming the holder's PID and host); a lock left by a
    process that is gone (same host) is taken over with a note. Released on exit, also after
    an error or Ctrl-C; a directory it created and nothing was written to is removed."""
    import json
    import os
    import socket
    import sys
    import time

    directory = Path(directory)
    created = not directory.exists()
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / LOCK
    me = {"pid": os.getpid(), "host": socket.gethostname(), "program": program}
    me["started"] = time.strftime("%Y-%m-%d %H:%M:%S")
    for _ in range(2):
        try:
            descriptor = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                holder = json.loads(path.read_text())
                pid, host = int(holder["pid"]), str(holder["host"])
            except (OSError, ValueError, KeyError, TypeError):
                holder, pid, host = {}, None, None
                try:  # unreadable: being written this moment, or left half-written long ago
                    young = time.time() - path.stat().st_mtime < 60
                except OSError:
                    young = False
                if young:
                    raise RunLocked(f"{directory} is being locked by another process") from None
            if pid is not None and (host != me["host"] or _alive(pid)):
                raise RunLocked(
                    f"{directory} is in use by experiments.{holder.get('program', '?')}, "
                    f"process {pid} on {host} (since {holder.get('started', '?')}): wait for "
                    f"it to end, or stop it; if that process is gone, delete {path}"
                ) from None
            print(
                f"note: taking over {path}, left by process {pid} on {host}, which is gone",
                file=sys.stderr,
            )
            path.unlink(missing_ok=True)
            continue
        with os.fdopen(descriptor, "w") as file:
            json.dump(me, file)
        break
    else:  # another process took the lock between our two tries
        raise RunLocked(f"{directory} was locked by another process as this one started")
    try:
        yield
    finally:
        path.unlink(missing_ok=True)
        if created and not any(directory.iterdir()):  # refused before writing: leave no trace
            directory.rmdir()


def text_argument(text: str) -> str:
    """An argparse ``type`` for a value that must not be empty (a path, a dataset id)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("must name a path, got ''")
    return text


def path_argument(text: str) -> Path:
    """An argparse ``type`` for paths: an empty string is refused (``Path("")`` would mean
    the current directory)."""
    return Path(text_argument(text))
