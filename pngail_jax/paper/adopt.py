"""Adopting finished sweeps as a plan's grids (``experiments.paper --adopt DIR``).

A grid of the plan that was run on its own (``experiments.sweep``, in parts, on another
machine) need not run again: a complete sweep whose config is the plan's grid's config, up to
``ADOPT_IGNORES`` (how often it checkpointed, what it logged to, its preset's name), is copied
into ``grids/<name>`` and kept like any finished grid. Its chunk length may differ from the
plan's, which makes it a different compiled program with the same numbers up to float rounding
(``tests/test_grid.py``); the page names every adopted grid, where it came from and its commit.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterable, Mapping
from pathlib import Path

from pngail_jax.config.run_config import RunConfig
from pngail_jax.demos import RELEASED_ACTION_SCALES
from pngail_jax.jobs.errors import RunError
from pngail_jax.storage.integrity import IntegrityError, read_json, write_json

# Config fields that do not change a grid's numbers (beyond float rounding for the chunk).
ADOPT_IGNORES = ("chunk_iterations", "log", "preset_name")
ADOPTED_FILE = "adopted.json"


def adopt_grids(
    directories: Iterable[Path],
    configs: Mapping[str, RunConfig],
    out: Path,
    allow_unsealed: bool = False,
) -> dict:
    """Copies each sweep of ``directories`` into ``out/grids/<name>`` of the planned grid
    (``configs``: name -> the ``RunConfig`` the plan would run) whose config it matches.
    Returns ``{name: {"from": directory, "commit": ...}}`` of every adoption so far (kept in
    ``out/adopted.json``). Raises ``RunError`` with one line on a sweep that is not finished,
    matches no planned grid, or whose grid the plan already has."""
    record = read_adopted(out)
    for directory in directories:
        source = str(Path(directory).absolute())
        saved = finished_sweep(Path(directory), allow_unsealed)
        name = matching_grid(Path(directory), saved, configs)
        target = out / "grids" / name
        if record.get(name, {}).get("from") == source and target.exists():
            continue  # adopted by an earlier call of the same command
        if target.exists():
            raise RunError(
                f"--adopt {directory}: the plan's grid {name} is already in {target}; remove "
                "that folder to adopt this sweep instead"
            )
        partial = target.with_name(f".{name}.adopting")
        shutil.rmtree(partial, ignore_errors=True)  # a copy cut short before
        shutil.copytree(directory, partial)
        partial.rename(target)
        commit = saved.get("provenance", {}).get("git_commit")
        record[name] = {"from": source, "commit": commit}
        write_json(out / ADOPTED_FILE, record)
        print(f"== {name}: adopted {directory} (commit {commit or 'unknown'})", flush=True)
    return record


def read_adopted(out: Path) -> dict:
    """The adoptions recorded in ``out/adopted.json`` (none: {})."""
    path = out / ADOPTED_FILE
    if not path.exists():
        return {}
    try:
        return read_json(path, "adoption record")
    except IntegrityError as error:
        raise RunError(f"{path}: {error}") from None


def finished_sweep(directory: Path, allow_unsealed: bool = False) -> dict:
    """``directory``'s config.json, if it is a complete sweep that ``runs.verify_run`` trusts
    (its seal, unless ``allow_unsealed``; its input files; metrics.csv whole and agreeing with
    summary.json; its policies' digests); else ``RunError``."""
    from pngail_jax.analysis.runs import UntrustedRun, verify_run

    try:
        saved = read_json(directory / "config.json", "sweep config")
        summary = read_json(directory / "summary.json", "sweep summary")
    except FileNotFoundError:
        raise RunError(
            f"--adopt {directory}: not a sweep run (no config.json and summary.json there)"
        ) from None
    except IntegrityError as error:
        raise RunError(f"--adopt {directory}: {error}") from None
    if not summary.get("complete"):
        done, total = summary.get("iterations_done"), summary.get("iterations")
        raise RunError(
            f"--adopt {directory}: not finished ({done} of {total} iterations); "
            f"finish it first with python -m experiments.sweep --resume {directory}"
        )
    try:
        for note in verify_run(directory, f"--adopt {directory}", allow_unsealed=allow_unsealed):
            print(f"note: {note}")
    except UntrustedRun as error:
        raise RunError(str(error)) from None
    return saved


def matching_grid(directory: Path, saved: dict, configs: Mapping[str, RunConfig]) -> str:
    """The name of the planned grid whose config ``saved`` (a config.json) is, up to
    ``ADOPT_IGNORES``; else ``RunError`` naming the differences from the grid of its task."""
    try:
        given = adoption_fields(RunConfig.from_dict(saved))
    except ValueError as error:
        raise RunError(f"--adopt {directory}: {error}") from None
    differences = {}
    for name, config in configs.items():
        planned = adoption_fields(config)
        changed = [key for key in planned if planned[key] != given.get(key)]
        if not changed:
            return name
        if config.env == given["env"]:
            differences[name] = changed
    if not differences:
        raise RunError(
            f"--adopt {directory}: the plan has no grid on {given['env']} "
            f"(its grids: {', '.join(configs)})"
        )
    name, changed = min(differences.items(), key=lambda item: len(item[1]))
    raise RunError(
        f"--adopt {directory}: not the plan's grid {name}: "
        + "; ".join(f"{key} {given.get(key)!r}, the plan's {adoption_fields(configs[name])[key]!r}"
                    for key in changed[:4])
    )  # fmt: skip


def adoption_fields(config: RunConfig) -> dict:
    """``config``'s fields but ``ADOPT_IGNORES``, as JSON would hold them (tuples as lists),
    with the action scale the loader applies in place of None (a sweep of the authors'
    Pendulum file given no ``--action-scale`` runs on its known scale, 2, as the plan does)."""
    values = json.loads(json.dumps(config.to_dict()))
    if values.get("action_scale") is None and config.demos is not None:
        name = Path(config.demos).name.removesuffix("_mixture.npy")
        values["action_scale"] = RELEASED_ACTION_SCALES.get(name, 1.0)
    return {key: value for key, value in values.items() if key not in ADOPT_IGNORES}
