"""Files you can trust: atomic writes, content digests of directories, strict JSON.

- ``atomic_path`` / ``atomic_write_text`` / ``write_json``: a file appears whole or not at all
  (written to a temporary sibling, flushed, then renamed over the target), so a kill never
  leaves a truncated summary, cache or checkpoint file behind.
- ``write_manifest`` / ``verify_manifest``: ``digests.json`` lists the SHA-256 and size of
  every file in a directory (a checkpoint, a saved policy). It is written last, so it also
  marks the directory complete; ``verify_manifest`` names the first file that is missing,
  truncated or changed.
- ``file_record`` / ``changed_inputs``: digests of a run's input files, recorded in its
  ``config.json`` and compared on ``--resume``.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import secrets
from collections.abc import Iterator
from pathlib import Path

MANIFEST_NAME = "digests.json"
_TEMPORARY_MARK = ".tmp-"
# A run directory's lock file, there only while a process writes the run (held by
# pngail_jax.storage.outputs.run_lock); here, beside the atomic writes, because manifests leave
# it out.
LOCK = ".pngail-run.lock"
# A run's list of the files it wrote, updated until its process ends (pngail_jax.storage.outputs
# .record_outputs): here for the same reason.
OUTPUT_LIST = ".pngail-outputs.json"


class IntegrityError(ValueError):
    """A file or directory whose content is not what was written; the message names it."""


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yields a temporary sibling of ``path`` to write; renames it onto ``path`` on success
    and removes it on any error. The temporary name keeps the suffix (``np.savez`` appends
    ``.npz`` to names without it)."""
    path = Path(path)
    temporary = path.parent / f".{path.stem}{_TEMPORARY_MARK}{secrets.token_hex(4)}{path.suffix}"
    try:
        yield temporary
        with open(temporary, "rb+") as written:
            os.fsync(written.fileno())
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    with atomic_path(path) as temporary:
        temporary.write_bytes(data)


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


def write_json(path: str | Path, document, indent: int | None = 2) -> None:
    """Writes ``document`` atomically as strict JSON: a NaN or inf raises instead of being
    written as the bare ``NaN`` most parsers reject (replace them with null first)."""
    atomic_write_text(path, json.dumps(document, indent=indent, allow_nan=False))


def read_json(path: str | Path, what: str = "JSON file"):
    """The parsed content of ``path``; ``IntegrityError`` naming the file if it is not JSON."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise IntegrityError(f"{path}: damaged {what}, not valid JSON ({error})") from None


def file_digest(path: str | Path) -> str:
    """``"sha256:<hex>"`` of the file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return f"sha256:{digest.hexdigest()}"


def file_record(path: str | Path) -> dict:
    """``{"path", "bytes", "sha256"}`` of one file (the path made absolute), or of a whole
    directory (a Minari dataset): its files' total size, and a digest of their relative
    paths and contents, so that a dataset rebuilt with other data is told apart."""
    path = Path(path).absolute()
    if path.is_dir():
        return {"path": str(path), "bytes": _directory_size(path), "sha256": _tree_digest(path)}
    return {"path": str(path), "bytes": path.stat().st_size, "sha256": file_digest(path)}


def _tree_files(directory: Path) -> list[Path]:
    return sorted(p for p in directory.rglob("*") if p.is_file())


def _directory_size(directory: Path) -> int:
    return sum(p.stat().st_size for p in _tree_files(directory))


def _tree_digest(directory: Path) -> str:
    digest = hashlib.sha256()
    for path in _tree_files(directory):
        digest.update(f"{path.relative_to(directory)}\0{file_digest(path)}\n".encode())
    return f"sha256:{digest.hexdigest()}"


def _files(directory: Path) -> list[Path]:
    """The files a manifest lists: not itself, temporaries, a run's lock (there only while a
    process writes: pngail_jax.storage.outputs.run_lock) or its list of files (updated after)."""
    return sorted(
        path
        for path in directory.rglob("*")
        if path.is_file()
        and path.name not in (MANIFEST_NAME, LOCK, OUTPUT_LIST)
        and _TEMPORARY_MARK not in path.name
    )


def write_manifest(directory: str | Path) -> dict:
    """Writes ``directory/digests.json`` (every file's size and SHA-256, by relative path)
    and returns it. Call it after the last file of the directory is written."""
    directory = Path(directory)
    files = {
        path.relative_to(directory).as_posix(): {
            "bytes": path.stat().st_size,
            "sha256": file_digest(path),
        }
        for path in _files(directory)
    }
    manifest = {"format_version": 1, "files": files}
    write_json(directory / MANIFEST_NAME, manifest)
    return manifest


def verify_manifest(directory: str | Path) -> None:
    """Raises ``IntegrityError`` naming the first file of ``directory`` that is missing,
    truncated or changed since ``write_manifest``, or the manifest itself if absent or
    damaged (an interrupted write, or a directory from a version without digests)."""
    directory = Path(directory)
    manifest_path = directory / MANIFEST_NAME
    if not manifest_path.exists():
        raise IntegrityError(f"{directory}: no {MANIFEST_NAME} (incomplete: its write stopped)")
    manifest = read_json(manifest_path, "digest list")
    files = manifest.get("files") if isinstance(manifest, dict) else None
    if not isinstance(files, dict) or not files:
        raise IntegrityError(f"{manifest_path}: damaged digest list (no files listed)")
    for name, expected in files.items():
        path = directory / name
        if not path.is_file():
            raise IntegrityError(f"{path}: missing")
        size = path.stat().st_size
        if size != expected.get("bytes"):
            raise IntegrityError(
                f"{path}: damaged ({size:,} bytes where {expected.get('bytes'):,} were written)"
            )
        if file_digest(path) != expected.get("sha256"):
            raise IntegrityError(
                f"{path}: damaged (its content differs from what was written: SHA-256 mismatch)"
            )


def changed_inputs(records: dict[str, dict]) -> list[str]:
    """One line per recorded input file (``{role: file_record}``) that is gone or whose
    content differs now."""
    changes = []
    for role, record in records.items():
        path = Path(record["path"])
        if not path.exists():
            changes.append(f"{role} {path} is gone")
        else:
            now = file_record(path)
            if now["bytes"] != record["bytes"] or now["sha256"] != record["sha256"]:
                changes.append(f"{role} {path} has changed since the run began")
    return changes


def json_digest(document) -> str:
    """``"sha256:<hex>"`` of a JSON document's canonical text (sorted keys, no spaces)."""
    text = json.dumps(document, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return "sha256:" + hashlib.sha256(text.encode()).hexdigest()


# Where a run keeps the seal of the config it began with (beside config.json).
CONFIG_SEAL = ".config.sealed.json"


def seal(path: str | Path, document) -> None:
    """Writes ``document`` and its digest to ``path``: what a run was created with, kept
    apart from the file a user may edit, so that a resume can compare the two."""
    write_json(path, {"sealed": document, "sha256": json_digest(document)})


def write_sealed(path: str | Path, document, seal_path: str | Path, sealed=None) -> None:
    """Writes a run's ``document`` (config.json, paper.json) to ``path`` after its seal at
    ``seal_path`` (of ``sealed``, the part a resume checks; None: the whole document), so
    that the document never exists without its seal. Every job that begins a run writes
    its record so."""
    seal(seal_path, document if sealed is None else sealed)
    write_json(path, document)


def sealed_differences(path: str | Path, document, prefix: str = "") -> list[str] | None:
    """The fields where ``document`` differs from the sealed one at ``path`` (``"a.b: was X,
    now Y"``), [] when equal, None when there is no seal (a run from an older version);
    IntegrityError when the seal itself is damaged."""
    path = Path(path)
    if not path.exists():
        return None
    record = read_json(path, "sealed config")
    sealed = record.get("sealed") if isinstance(record, dict) else None
    if sealed is None or json_digest(sealed) != record.get("sha256"):
        raise IntegrityError(f"{path}: damaged (its content differs from its digest)")
    return document_differences(sealed, document, prefix)


def document_differences(was, now, prefix: str = "") -> list[str]:
    """The fields where JSON document ``now`` differs from ``was``, one line each
    (``"a.b: was X, now Y"``, ``added``, ``removed``); [] when equal."""
    if isinstance(was, dict) and isinstance(now, dict):
        found = []
        for key in sorted(set(was) | set(now), key=str):
            name = f"{prefix}{key}"
            if key not in now:
                found.append(f"{name}: removed (was {json.dumps(was[key])})")
            elif key not in was:
                found.append(f"{name}: added ({json.dumps(now[key])})")
            else:
                found += document_differences(was[key], now[key], f"{name}.")
        return found
    if was != now:
        return [f"{prefix.rstrip('.')}: was {json.dumps(was)}, now {json.dumps(now)}"]
    return []
