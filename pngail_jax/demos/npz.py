"""Our ``.npz`` schema, version 1: arrays ``observations`` float32[N, O], ``actions``
float32[N, A], optional ``confidence`` float32[N], ``labelled`` bool[N], ``trajectory_ids``
int32[N], plus ``metadata_json`` (a JSON string) and ``format_version``."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from pngail_jax.demos.files import load_numpy, not_numbers
from pngail_jax.demos.types import DemonstrationError, Demonstrations

NPZ_FORMAT_VERSION = 1


def save_npz(path: str | Path, demos: Demonstrations) -> None:
    arrays = {"observations": demos.observations, "actions": demos.actions}
    for name in ("confidence", "labelled", "trajectory_ids"):
        if getattr(demos, name) is not None:
            arrays[name] = getattr(demos, name)
    np.savez(
        path,
        **arrays,
        metadata_json=np.asarray(json.dumps(demos.metadata)),
        format_version=np.asarray(NPZ_FORMAT_VERSION),
    )


def load_npz(path: str | Path) -> Demonstrations:
    """Loads our ``.npz`` schema (module docstring); errors name the file."""
    where = f"demonstrations .npz {path}"
    arrays = load_numpy(path, "demonstrations .npz", archive=True)
    if "format_version" not in arrays:
        raise DemonstrationError(
            f"{where}: has no array 'format_version' (not written by save_npz? this version "
            f"reads format_version {NPZ_FORMAT_VERSION})"
        )
    version = arrays["format_version"]
    if version.shape != () or version.dtype.kind not in "iu":
        raise DemonstrationError(
            f"{where}: format_version must be one integer, got {version.dtype} of shape "
            f"{version.shape}"
        )
    version = int(version)
    if version != NPZ_FORMAT_VERSION:
        raise DemonstrationError(
            f"{where}: unsupported format_version {version!r} "
            f"(this version reads {NPZ_FORMAT_VERSION})"
        )
    for name in ("observations", "actions"):
        if name not in arrays:
            raise DemonstrationError(
                f"{where}: has no array {name!r} (it has {', '.join(sorted(arrays))})"
            )
    fields = {
        name: arrays[name]
        for name in ("observations", "actions", "confidence", "labelled", "trajectory_ids")
        if name in arrays
    }
    for name, array in fields.items():
        if array.dtype.kind not in "biuf":
            raise DemonstrationError(f"{where}: array {name!r} {not_numbers(array)}")
    metadata = _npz_metadata(arrays.get("metadata_json"), where)
    try:
        return Demonstrations(metadata=metadata, **fields)
    except DemonstrationError as error:
        raise DemonstrationError(f"{where}: {error}") from None


def _npz_metadata(metadata_json: np.ndarray | None, where: str) -> dict[str, Any]:
    """The metadata dict of an ``.npz`` file's ``metadata_json`` (empty when absent), with
    usable random / optimal returns when it has both; raises naming ``where``."""
    if metadata_json is None:
        return {}
    if metadata_json.shape != () or metadata_json.dtype.kind != "U":
        raise DemonstrationError(
            f"{where}: metadata_json must be one string, got {metadata_json.dtype} of shape "
            f"{metadata_json.shape}"
        )
    try:
        metadata = json.loads(str(metadata_json))
    except ValueError as error:
        raise DemonstrationError(f"{where}: metadata_json is not valid JSON ({error})") from None
    if not isinstance(metadata, dict):
        raise DemonstrationError(f"{where}: metadata_json must be a JSON object")
    if "random_return" in metadata and "optimal_return" in metadata:
        returns = metadata["random_return"], metadata["optimal_return"]
        numbers = all(isinstance(x, int | float) and not isinstance(x, bool) for x in returns)
        if not (numbers and all(math.isfinite(x) for x in returns) and returns[0] != returns[1]):
            raise DemonstrationError(
                f"{where}: metadata random_return {returns[0]!r} and optimal_return "
                f"{returns[1]!r} must be two different finite numbers (normalised returns "
                "divide by their difference)"
            )
        if returns[0] > returns[1]:  # make_demos at a tiny budget: usable, but say so
            warnings.warn(
                f"{where}: its optimal_return {returns[1]:.1f} is below its random_return "
                f"{returns[0]:.1f}: normalised returns run backwards (make it with more "
                "--iterations)",
                stacklevel=3,
            )
    return metadata
