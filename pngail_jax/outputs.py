"""The output contract: which program's run a directory holds, whether a program may write
there, and the lock a writing process holds.

An output directory is new, or empty, or a run of the same program (marked so when it was
created) that the user asked to resume or to replace with ``overwrite``. Anything else is
refused before any computation, naming what is in the way. Every job and program claims its
directory the same way, with ``claimed``: refuse, lock, check again (another process may have
written meanwhile), and prepare (mark, and empty an old run) when the caller is ready to
write. A program's flag parser may call ``output_refusal`` earlier, to refuse in one line
before anything is built.
"""

from __future__ import annotations

import contextlib
import dataclasses
from pathlib import Path

from pngail_jax.integrity import LOCK, atomic_write_text

MARKER = ".pngail-run.json"
# Runs made before the marker existed are known by files of their program's own (the most
# specific first: train_rl writes a config.json too, without the sweep's "resolved").
LEGACY_MARKS = {
    "paper": ("paper.json",),
    "compare_settings": ("comparison.json",),
    "make_demos": ("demos.npz", "normalizer.json"),  # normalizer.json: one cut short
    "train_rl": ("policy.json",),
}
RESUMABLE = {"sweep", "paper", "offline"}
# What each program's run writes at the top of its directory (fnmatch patterns): all that
# --overwrite removes; a run folder holding anything else is not overwritten (its owner's
# tests check that every name a real run writes is listed here).
_LOGS = ("tensorboard", "wandb")
OWNED = {
    "sweep": ("config.json", ".config.sealed.json", "metrics.csv", "curves.png",
              "diagnostics.png", "summary.md", "summary.json", "policies", "checkpoints",
              *_LOGS),
    "offline": ("config.json", ".config.sealed.json", "metrics.csv", "curves.png",
                "summary.md", "summary.json", "checkpoints", *_LOGS),
    "train_rl": ("config.json", ".config.sealed.json", "metrics.csv", "learning_curve.png",
                 "policy.json", "policy_params", "digests.json", "checkpoints"),
    "make_demos": ("demos.npz", "normalizer.json", "checkpoints"),
    "compare_settings": ("comparison.json", "comparison.md", "comparison.png",
                         "reference*", "table*", "mid-fast", "wide-fast*"),  # + its arms' runs
    "paper": ("paper.json", ".paper.sealed.json", "grids", "demos", "timings.json",
              "adopted.json", "README.md", "results.json", "*.png"),
    "paper-page": ("README.md", "results.json", "*.png"),
    "compare": ("compare.json", "compare.md", "*.png"),
}  # fmt: skip


def unaccounted(directory: Path, program: str) -> list[str]:
    """The names at the top of ``directory`` that a run of ``program`` does not write (its
    ``OWNED`` list; the marker and the lock are every program's), sorted."""
    from fnmatch import fnmatch

    patterns = (*OWNED.get(program, ()), MARKER, LOCK)
    return sorted(
        path.name
        for path in Path(directory).iterdir()
        if not any(fnmatch(path.name, pattern) for pattern in patterns)
    )


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
            if "resolved" in document:
                return "sweep"
            return "train_rl" if "rollout" in document or "trpo" in document else None
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
            foreign = unaccounted(directory, program)
            if not foreign:
                return None
            shown = ", ".join(foreign[:5]) + (
                f" and {len(foreign) - 5} more" if len(foreign) > 5 else ""
            )
            return (
                f"{flag} {directory} holds a run of experiments.{program} and files it did not "
                f"make ({shown}): --overwrite replaces only its own; move those, or choose "
                f"another {flag}"
            )
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


def prepare_output(directory: Path, program: str, overwrite: bool = False) -> None:
    """Creates ``directory`` and marks it as ``program``'s run; with ``overwrite``, first
    removes what a run of ``program`` writes there (``OWNED``), and nothing else:
    ``claim_output`` allowed it only for a run of ``program`` holding nothing more."""
    import json
    import shutil

    directory = Path(directory)
    if overwrite and directory.exists() and output_owner(directory) == program:
        keep = set(unaccounted(directory, program)) | {LOCK}  # the lock: this process's
        for path in directory.iterdir():
            if path.name in keep:
                continue
            shutil.rmtree(path) if path.is_dir() and not path.is_symlink() else path.unlink()
    directory.mkdir(parents=True, exist_ok=True)
    if not (directory / MARKER).exists():
        atomic_write_text(directory / MARKER, json.dumps({"program": program}) + "\n")


class OutputRefused(Exception):
    """A directory a program may not write to; the one-line message names what is in the
    way."""


class RunLocked(OutputRefused):
    """Another live process holds the run's lock (the message names it)."""


@dataclasses.dataclass(frozen=True)
class Claim:
    """A held claim on an output directory (``claimed``)."""

    directory: Path
    program: str
    overwrite: bool
    resume: bool

    def prepare(self) -> None:
        """Marks the directory as the program's run (emptying an old one with ``overwrite``);
        nothing for a resumed run, which keeps its directory as it is. Called once the job
        is ready to write, so that an old run stays until a new one can replace it."""
        if not self.resume:
            prepare_output(self.directory, self.program, overwrite=self.overwrite)


@contextlib.contextmanager
def claimed(
    directory: Path,
    program: str,
    *,
    overwrite: bool = False,
    resume: bool = False,
    wait: bool = False,
):
    """The one way a job takes an output directory: refuse (``output_refusal``), lock
    (``run_lock``), check again under the lock, and yield a ``Claim`` whose ``prepare`` marks
    it. ``resume``: the directory holds the program's run, which the caller continues (the
    caller has checked it; it is locked, not checked for emptiness). ``wait``: a lock held by
    another live process is waited for (one line says whose) instead of refused. Raises
    ``OutputRefused`` (``RunLocked`` for a held lock) with one line."""
    directory = Path(directory)

    def refuse_unless_free():
        refusal = None if resume else output_refusal(directory, program, overwrite)
        if refusal:
            raise OutputRefused(refusal)

    refuse_unless_free()
    with run_lock(directory, program, wait=wait):
        refuse_unless_free()
        yield Claim(directory, program, overwrite, resume)


def _alive(pid: int) -> bool:
    import os

    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


WAIT_SECONDS = 2.0  # how often a waiting process looks at a held lock again


@contextlib.contextmanager
def run_lock(directory: Path, program: str, wait: bool = False):
    """Holds ``directory``'s run lock while a program writes there: a second process on the
    same run is refused (``RunLocked``, naming the holder's PID and host), or with ``wait``
    waits for it (saying so in one line); a lock left by a process that is gone (same host) is
    taken over with a note. Released on exit, also after an error or Ctrl-C; a directory it
    created and nothing was written to is removed."""
    import os
    import socket
    import time

    directory = Path(directory)
    created = not directory.exists()
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / LOCK
    wait_announced = False
    me = {"pid": os.getpid(), "host": socket.gethostname(), "program": program}
    me["started"] = time.strftime("%Y-%m-%d %H:%M:%S")
    while True:
        try:
            _take_lock(directory, path, me)
            break
        except RunLocked as error:
            if not wait:
                raise
            if not wait_announced:
                print(f"waiting: {error}", flush=True)
                wait_announced = True
            time.sleep(WAIT_SECONDS)
    try:
        yield
    finally:
        path.unlink(missing_ok=True)
        if created and not any(directory.iterdir()):  # refused before writing: leave no trace
            directory.rmdir()


def _take_lock(directory: Path, path: Path, me: dict) -> None:
    """Creates the lock file ``path`` holding ``me``, taking over one whose process is gone;
    ``RunLocked`` when a live process holds it."""
    import json
    import os
    import sys
    import time

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
        return
    # another process took the lock between our two tries
    raise RunLocked(f"{directory} was locked by another process as this one started")
