"""Safe reading of ``.npy`` and ``.npz`` files: every file goes through ``load_numpy`` with
``allow_pickle=False``; an empty, truncated or corrupt file, pickled objects, strings or a
missing array end in a ``DemonstrationError`` that names the file, its role and the problem."""

from __future__ import annotations

import math
import zipfile
import zlib
from pathlib import Path

import numpy as np

from pngail_jax.demos.types import DemonstrationError

# The first bytes of a .npy file and of a .npz (zip) archive.
NPY_MAGIC = b"\x93NUMPY"

ZIP_MAGICS = (b"PK\x03\x04", b"PK\x05\x06")


def load_numpy(path: str | Path, role: str, *, archive: bool = False):
    """The array of a ``.npy`` file (``archive=False``) or the arrays of a ``.npz`` archive (a
    dict by name), read with ``allow_pickle=False``.

    Raises ``FileNotFoundError`` for a missing file and ``DemonstrationError`` for anything
    else that is not a clean NumPy file (empty, truncated, corrupt, pickled objects; for a
    ``.npy`` file also values that are not real numbers), each message naming ``role`` (e.g.
    ``"mixture file"``) and ``path``.
    """
    path = Path(path)
    where = f"{role} {path}"
    if not path.exists():
        raise FileNotFoundError(f"{role} not found: {path}")
    if path.is_dir():
        raise DemonstrationError(f"{where}: is a directory, not a file")
    num_bytes = path.stat().st_size
    if num_bytes == 0:
        raise DemonstrationError(f"{where}: is empty (0 bytes)")
    with path.open("rb") as stream:
        start = stream.read(len(NPY_MAGIC))
        stream.seek(0)
        if start.startswith(ZIP_MAGICS) != archive:
            raise DemonstrationError(f"{where}: {_wrong_container(start, archive)}")
        problem = None if archive else _npy_problem(stream, num_bytes)
    if problem:
        raise DemonstrationError(f"{where}: {problem}")
    try:
        return _read_npz(path, where) if archive else _read_npy(path, where)
    except DemonstrationError:
        raise
    except (
        OSError,
        EOFError,
        ValueError,
        KeyError,
        NotImplementedError,
        RuntimeError,
        zipfile.BadZipFile,
        zlib.error,
    ) as error:
        kind = "NumPy .npz archive" if archive else "NumPy .npy file"
        detail = (str(error).splitlines() or [type(error).__name__])[0][:200]
        raise DemonstrationError(
            f"{where}: not a readable {kind}, truncated or corrupt ({detail})"
        ) from None


def _wrong_container(start: bytes, archive: bool) -> str:
    if not archive:
        return "is a .npz archive, expected a .npy file"
    kind = "a .npy file" if start == NPY_MAGIC else "not a zip archive"
    return f"not a NumPy .npz archive ({kind})"


def _read_npy(path: Path, where: str) -> np.ndarray:
    array = np.load(path, allow_pickle=False)
    if array.dtype.kind not in "biuf":
        raise DemonstrationError(f"{where}: {not_numbers(array)}")
    return array


def _read_npz(path: Path, where: str) -> dict[str, np.ndarray]:
    """Every ``.npy`` member of the archive, each checked by its header before it is read."""
    arrays = {}
    with np.load(path, allow_pickle=False) as npz:
        for info in npz.zip.infolist():
            if not info.filename.endswith(".npy"):
                continue  # np.savez writes only .npy members; others are not ours
            name = info.filename.removesuffix(".npy")
            with npz.zip.open(info) as member:
                problem = _npy_problem(member, info.file_size)
            if problem:
                raise DemonstrationError(f"{where}: array {name!r} {problem}")
            arrays[name] = npz[name]
    return arrays


def _npy_problem(stream, num_bytes: int) -> str | None:
    """What is wrong with the ``.npy`` data of ``num_bytes`` bytes at ``stream``'s start, read
    from its header alone (no data is read), or None when the header is sound."""
    try:
        version = np.lib.format.read_magic(stream)
    except ValueError:
        return "is not a NumPy .npy file (bad header)"
    if version not in ((1, 0), (2, 0), (3, 0)):
        return f"is not a NumPy .npy file (unknown format version {version[0]}.{version[1]})"
    # Version 3.0 differs from 2.0 only in decoding non-ASCII field names, which no array of
    # numbers has.
    read_header = (
        np.lib.format.read_array_header_1_0
        if version == (1, 0)
        else np.lib.format.read_array_header_2_0
    )
    try:
        shape, _, dtype = read_header(stream)
    except Exception:  # untrusted bytes: any failure to parse the header means a corrupt one
        return "is not a NumPy .npy file (corrupt header)"
    if dtype.hasobject:
        return "holds pickled Python objects, which are not loaded for safety"
    if any(size < 0 for size in shape):
        return f"is not a NumPy .npy file (corrupt header: shape {shape})"
    expected = math.prod(shape) * dtype.itemsize
    found = num_bytes - stream.tell()
    if found < expected:
        return (
            f"is truncated: expected {expected} bytes of data for shape {shape} "
            f"{dtype}, found {found}"
        )
    return None


def not_numbers(array: np.ndarray) -> str:
    kinds = {"U": "strings", "S": "bytes", "c": "complex numbers", "M": "dates", "m": "times"}
    what = kinds.get(array.dtype.kind, "values")
    return f"holds {what} (dtype {array.dtype}), expected real numbers"


def read_numbers(path: str | Path) -> np.ndarray:
    """The numbers of a ``.npy`` file, or of a text file with one number per line."""
    path = Path(path)
    if path.suffix == ".npy":
        return load_numpy(path, "confidence file")
    try:
        return np.loadtxt(path, ndmin=1)
    except ValueError as error:
        raise DemonstrationError(
            f"confidence file {path}: expected one number per line: {error}"
        ) from None
