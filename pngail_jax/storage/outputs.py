"""The output contract: which program's run a directory holds, whether a program may write
there, and the lock a writing process holds.

An output directory is new, or empty, or a run of the same program (marked so when it was
created) that the user asked to resume or to replace with ``overwrite``. Anything else is
refused before any computation, naming what is in the way. Every job and program claims its
directory the same way, with ``claimed``: refuse, lock, check again (another process may have
written meanwhile), and prepare (mark, and empty an old run) when the caller is ready to
write. A program's flag parser may call ``output_refusal`` earlier, to refuse in one line
before anything is built.

``--overwrite`` removes exactly the files the run wrote, never a name that matches: a run keeps
the list of them in ``.pngail-outputs.json`` (``record_outputs``, brought up to date when its
claim ends, normally or not, and after each chunk's checkpoint), and a folder holding anything
else, at any depth, is refused, naming it.
"""

from __future__ import annotations

import contextlib
import dataclasses
from pathlib import Path

from pngail_jax.storage.integrity import LOCK, OUTPUT_LIST, atomic_write_text, write_json

MARKER = ".pngail-run.json"
# OUTPUT_LIST (".pngail-outputs.json", beside the lock in integrity): the files a run wrote, by
# relative path (an empty folder with a trailing /), which is what --overwrite removes.
# Runs made before the marker existed are known by files of their program's own (the most
# specific first: train_rl writes a config.json too, without the sweep's "resolved").
LEGACY_MARKS = {
    "paper": ("paper.json",),
    "compare_settings": ("comparison.json",),
    "make_demos": ("demos.npz", "normalizer.json"),  # normalizer.json: one cut short
    "train_rl": ("policy.json",),
}
RESUMABLE = {"sweep", "paper", "offline", "make_demos", "train_rl"}
# The names each program's run writes at the top of its directory (fnmatch patterns; its
# owner's tests check that every name a real run writes is listed here). A run lists as its
# own (OUTPUT_LIST) only what it wrote under these names; --overwrite removes only what that
# list names, never a file a pattern matches (a user's mine.png beside a page's *.png).
_LOGS = ("tensorboard", "wandb")
OWNED = {
    "sweep": ("config.json", ".config.sealed.json", "metrics.csv", "curves.png",
              "diagnostics.png", "summary.md", "summary.json", "policies", "checkpoints",
              *_LOGS),
    "offline": ("config.json", ".config.sealed.json", "metrics.csv", "curves.png",
                "summary.md", "summary.json", "checkpoints", *_LOGS),
    "train_rl": ("config.json", ".config.sealed.json", "metrics.csv", "learning_curve.png",
                 "policy.json", "policy_params", "digests.json", "checkpoints"),
    "make_demos": ("config.json", ".config.sealed.json", "demos.npz", "normalizer.json",
                   "checkpoints", "training"),
    "compare_settings": ("comparison.json", "comparison.md", "comparison.png",
                         "reference*", "table*", "mid-fast", "wide-fast*"),  # + its arms' runs
    "paper": ("paper.json", ".paper.sealed.json", "grids", "demos", "timings.json",
              "adopted.json", "README.md", "results.json", "*.png"),
    "paper-page": ("README.md", "results.json", "*.png"),
    "compare": ("compare.json", "compare.md", "*.png"),
}  # fmt: skip


def unaccounted(directory: Path, program: str) -> list[str]:
    """The names at the top of ``directory`` that a run of ``program`` does not write (its
    ``OWNED`` list; the marker, the lock and the list of files are every program's), sorted."""
    return sorted(path.name for path in Path(directory).iterdir() if not _owned(path.name, program))


# Every program's at the top of its run, and in no list of files: the marker, the lock, the list.
_RUN_FILES = (MARKER, LOCK, OUTPUT_LIST)


def _owned(name: str, program: str) -> bool:
    """Whether a run of ``program`` writes ``name`` at the top of its directory."""
    from fnmatch import fnmatch

    return name in _RUN_FILES or any(fnmatch(name, pattern) for pattern in OWNED.get(program, ()))


def _entries(directory: Path) -> list[tuple[str, bool]]:
    """Everything in ``directory`` at any depth, as (relative path, whether a folder), each
    folder before its contents; a symbolic link is an entry, never followed; the marker, lock
    and list of files at the top are left out."""
    import os

    found: list[tuple[str, bool]] = []

    def visit(folder: str, prefix: str) -> None:
        try:
            with os.scandir(folder) as scan:
                listing = sorted(scan, key=lambda entry: entry.name)
        except (FileNotFoundError, NotADirectoryError):  # removed meanwhile
            return
        for entry in listing:
            if prefix or entry.name not in _RUN_FILES:
                found.append((prefix + entry.name, entry.is_dir(follow_symlinks=False)))
                if found[-1][1]:
                    visit(entry.path, f"{prefix}{entry.name}/")

    visit(str(directory), "")
    return found


def _listed(directory: Path) -> set[str] | None:
    """The files ``directory``'s run listed as its own (``OUTPUT_LIST``; an empty folder with
    a trailing /), None where there is no list; ``ValueError`` naming it when it is damaged."""
    import json

    path = Path(directory) / OUTPUT_LIST
    try:
        document = json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as error:
        raise ValueError(f"its list of files {path} cannot be read ({error})") from None
    files = document.get("files") if isinstance(document, dict) else None
    if not isinstance(files, list) or not all(isinstance(name, str) for name in files):
        raise ValueError(f"its list of files {path} is damaged (no list of paths)")
    return set(files)


def _changed_since(path: Path, since: float) -> bool:
    """Whether ``path`` was created or changed at or after ``since`` (the status change time
    counts: a copy that keeps its source's modification time is new all the same)."""
    status = path.lstat()
    return max(status.st_mtime, status.st_ctime) >= since


def record_outputs(directory: Path, program: str, since: float) -> list[str] | None:
    """Brings the list of the files ``program``'s run wrote in ``directory`` (``OUTPUT_LIST``)
    up to date and returns it: adds each file, and each empty folder, that lies under a name the
    run writes at the top (``OWNED``) and was created or changed at or after ``since`` (when
    the claim began, by the directory's filesystem: ``Claim.since``), so that a file already
    there when the program started is never taken for its own; drops what is no longer there.
    Nothing (None) where there is no list (a run from before the lists, a directory not yet
    prepared) or a damaged one, which ``--overwrite`` then refuses."""
    directory = Path(directory)
    try:
        listed = _listed(directory)
    except ValueError:
        return None
    if listed is None:
        return None
    entries = _entries(directory)
    parents = {relative.rsplit("/", 1)[0] for relative, _ in entries if "/" in relative}
    files = set()
    for relative, folder in entries:
        if folder and relative in parents:
            continue  # a folder that holds something is implied by what it holds
        name = f"{relative}/" if folder else relative
        if name in listed:
            files.add(name)
            continue
        try:
            if _owned(relative.split("/")[0], program) and _changed_since(
                directory / relative, since
            ):
                files.add(name)
        except FileNotFoundError:  # removed meanwhile
            continue
    if files != listed:
        write_json(directory / OUTPUT_LIST, {"program": program, "files": sorted(files)})
    return sorted(files)


def output_owner(directory: Path) -> str | None:
    """The program whose run ``directory`` holds (its marker, else a legacy file, else what
    its config.json says: a run copied without its dot-files is still known), or None."""
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
    if config.is_file():  # today's layout names its program (analysis.runs.run_document)
        try:
            document = json.loads(config.read_text())
        except (OSError, ValueError):
            return None
        if isinstance(document, dict):
            if document.get("program") in ("offline", "train_rl", "make_demos"):
                return document["program"]
            # The flat layouts before it: the sweep's has what it resolved; train_rl's has not.
            if "resolved" in document:
                return "sweep"
            return "train_rl" if "rollout" in document or "trpo" in document else None
    return None


def output_refusal(
    directory: Path, program: str, overwrite: bool = False, flag: str = "--out"
) -> str | None:
    """Why ``directory`` may not receive ``program``'s outputs, or None when it may: it is new
    or empty (its own marker and empty list of files alone, left by a start that failed, count
    as empty), or holds a run of ``program`` and ``overwrite`` is set and nothing but the run's
    files is there (``overwrite_refusal``). The run lock is not content. Reads only."""
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
    if not contents or (owner == program and set(contents) <= {MARKER, OUTPUT_LIST}):
        return None
    if owner == program:
        if overwrite:
            return overwrite_refusal(directory, program, flag)
        resume = f"--resume {directory} to continue it, " if program in RESUMABLE else ""
        return (
            f"{flag} {directory} already holds a run of experiments.{program}: {resume}pass "
            f"--overwrite to replace it, or choose another {flag}"
        )
    what = (
        f"a run of experiments.{owner}" if owner else f"files it did not make ({_shown(contents)})"
    )
    return (
        f"{flag} {directory} is not empty: it holds {what}; experiments.{program} writes only "
        f"into a new or empty directory, or over its own run: choose another {flag}"
    )


def _shown(names: list[str]) -> str:
    """Up to five of ``names``, and how many more."""
    more = f" and {len(names) - 5} more" if len(names) > 5 else ""
    return ", ".join(names[:5]) + more


def overwrite_refusal(directory: Path, program: str, flag: str = "--out") -> str | None:
    """Why ``--overwrite`` may not replace the run of ``program`` in ``directory``, or None
    when everything in it, at any depth, is the run's: in the list of files it wrote
    (``OUTPUT_LIST``, ``record_outputs``), or its marker, lock or list. Whatever else is there
    (a user's file in ``checkpoints/``, a ``wandb/`` folder the run did not write, a
    ``mine.png``) is named, up to five.

    A run from before the lists has no record of what it wrote, and a name does not say who
    wrote a file (the reason for the lists). It is replaced only when it holds nothing but
    files at its top named exactly as files its program writes there (``OWNED``'s names
    without a wildcard: ``demos.npz``, ``comparison.json``, ``config.json``), which any run of
    the program would write over anyway; a folder (a user's file in ``checkpoints/`` looks like
    the run's) or a name only a wildcard matches refuses, asking the user to delete the run."""
    return _overwrite_check(Path(directory), program, flag)[0]


def _overwrite_check(directory: Path, program: str, flag: str):
    """``overwrite_refusal``'s answer, and the entries (``_entries``) it judged."""
    entries = _entries(directory)
    try:
        listed = _listed(directory)
    except ValueError as error:
        return (
            f"{flag} {directory} holds a run of experiments.{program}, but {error}: "
            f"--overwrite cannot tell the run's files from others; delete the run yourself, or "
            f"choose another {flag}"
        ), entries
    tops = [(relative, folder) for relative, folder in entries if "/" not in relative]
    if listed is None:  # a run from before the lists
        foreign = [relative for relative, _ in tops if not _owned(relative, program)]
        unknown = [relative for relative, folder in tops
                   if folder or relative not in OWNED.get(program, ())]  # fmt: skip
    else:
        foreign, unknown = _unlisted(entries, listed), []
    if foreign:
        return (
            f"{flag} {directory} holds a run of experiments.{program} and files it did not "
            f"make ({_shown(foreign)}): --overwrite replaces only its own; move those, or choose "
            f"another {flag}"
        ), entries
    if unknown:
        return (
            f"{flag} {directory} holds a run of experiments.{program} made before runs listed "
            f"their files ({OUTPUT_LIST}): --overwrite cannot tell its files in "
            f"{_shown(unknown)} from others; delete the run yourself, or choose another {flag}"
        ), entries
    return None, entries


def _unlisted(entries: list[tuple[str, bool]], listed: set[str]) -> list[str]:
    """The entries not in ``listed`` (a folder is in it when it holds a listed entry, or is
    listed empty), each shown once: a folder not listed hides what it holds."""
    folders = {name.rstrip("/") for name in listed if name.endswith("/")}
    for name in listed:
        parts = name.rstrip("/").split("/")
        folders.update("/".join(parts[:end]) for end in range(1, len(parts)))
    foreign: list[str] = []
    for relative, folder in entries:  # each folder before what it holds
        if any(relative.startswith(f"{other}/") for other in foreign):
            continue
        if relative not in (folders if folder else listed):
            foreign.append(relative)
    return foreign


def prepare_output(directory: Path, program: str, overwrite: bool = False) -> None:
    """Creates ``directory`` and marks it as ``program``'s run, with an empty list of its files
    (``OUTPUT_LIST``) when nothing else is there yet. With ``overwrite``, first removes exactly
    the files its run of ``program`` listed, then the folders they leave empty; when anything
    else is there (``overwrite_refusal``) it raises ``OutputRefused`` and removes nothing."""
    import json

    directory = Path(directory)
    emptied = overwrite and directory.exists() and output_owner(directory) == program
    if emptied:
        refusal, entries = _overwrite_check(directory, program, "--out")
        if refusal:
            raise OutputRefused(refusal)
        for relative, folder in entries:  # every one the run's (checked above)
            if not folder:
                (directory / relative).unlink(missing_ok=True)
        for relative, folder in reversed(entries):  # each folder after what it held
            if folder:
                with contextlib.suppress(OSError):  # something written there meanwhile: kept
                    (directory / relative).rmdir()
    directory.mkdir(parents=True, exist_ok=True)
    if not (directory / MARKER).exists():
        atomic_write_text(directory / MARKER, json.dumps({"program": program}) + "\n")
    if emptied or (output_owner(directory) == program and not _entries(directory)):
        write_json(directory / OUTPUT_LIST, {"program": program, "files": []})


class OutputRefused(Exception):
    """A directory a program may not write to; the one-line message names what is in the
    way."""


class RunLocked(OutputRefused):
    """Another live process holds the run's lock (the message names it)."""


@dataclasses.dataclass(frozen=True)
class Claim:
    """A held claim on an output directory (``claimed``); ``since``: when it began, by the
    directory's filesystem (the time of its lock), from which on what appears there under the
    program's names is the run's (``record_outputs``)."""

    directory: Path
    program: str
    overwrite: bool
    resume: bool
    since: float

    def prepare(self) -> None:
        """Marks the directory as the program's run (emptying an old one with ``overwrite``);
        nothing for a resumed run, which keeps its directory as it is. Called once the job
        is ready to write, so that an old run stays until a new one can replace it."""
        if not self.resume:
            prepare_output(self.directory, self.program, overwrite=self.overwrite)

    def record(self) -> None:
        """Brings the run's list of its files up to date (``record_outputs``); a disk that
        refuses is said in one line, and the list stays as it was (``--overwrite`` then names
        what it misses)."""
        import sys

        try:
            record_outputs(self.directory, self.program, self.since)
        except OSError as error:
            print(
                f"note: cannot update {self.directory / OUTPUT_LIST} "
                f"({error.strerror or error}): --overwrite will name the files it misses",
                file=sys.stderr,
            )


_HELD: list[Claim] = []  # the claims this process holds, outermost first


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
    another live process is waited for (one line says whose) instead of refused. On leaving,
    however it leaves, the run's list of its files is brought up to date (``Claim.record``).
    Raises ``OutputRefused`` (``RunLocked`` for a held lock) with one line."""
    directory = Path(directory)

    def refusal():
        return None if resume else output_refusal(directory, program, overwrite)

    # The program's run while a process writes it lists only part of its files yet: the lock
    # refuses (or waits), and the check under it decides.
    first = refusal()
    written_now = overwrite and (directory / LOCK).exists() and output_owner(directory) == program
    if first and not written_now:
        raise OutputRefused(first)
    with run_lock(directory, program, wait=wait):
        again = refusal()
        if again:
            raise OutputRefused(again)
        claim = Claim(directory, program, overwrite, resume, (directory / LOCK).stat().st_mtime)
        _HELD.append(claim)
        try:
            yield claim
        finally:
            _HELD.remove(claim)
            claim.record()
            record_held_outputs(directory)  # a run it lies in (a plan's grid) lists it now too


def record_held_outputs(path: Path | None) -> None:
    """Brings up to date the list of files (``Claim.record``) of each run this process holds a
    claim on that ``path`` lies in; ``jobs.chunks.run_chunks`` calls it after each chunk's
    checkpoint, so that a run killed later lists what it wrote up to there. Nothing for None."""
    if path is None:
        return
    path = Path(path).resolve()
    for claim in reversed(_HELD):
        if path.is_relative_to(claim.directory.resolve()):
            claim.record()


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
