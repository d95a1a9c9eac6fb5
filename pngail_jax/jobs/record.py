"""A sweep's record and the checks of its resume: config.json (``runs.run_document``'s
layout: the config, what it resolved to, the digests of its input files, provenance) and
its seal; ``load_saved``, which reads a
run back and refuses a changed config, method or input; which outputs a resume finds
finished or stale."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from collections.abc import Sequence
from pathlib import Path

from pngail_jax.adversarial import methods
from pngail_jax.adversarial.methods import preset_record
from pngail_jax.analysis.runs import (
    changed_inputs_refusal,
    read_run_config,
    run_document,
    sealed_part,
)
from pngail_jax.config.run_config import RunConfig
from pngail_jax.config.saved import provenance, upgrade_saved_config
from pngail_jax.config.validation import ConfigError
from pngail_jax.demos.minari import MINARI_PREFIX
from pngail_jax.jobs.build import BuiltRun
from pngail_jax.jobs.demonstrations import input_files
from pngail_jax.jobs.errors import RunError
from pngail_jax.storage.integrity import (
    CONFIG_SEAL,
    IntegrityError,
    changed_inputs,
    read_json,
    write_sealed,
)


@dataclasses.dataclass
class SavedRun:
    """A resumed run's config.json: its config, the demonstrations it used, its devices."""

    config: RunConfig
    demos_path: str
    device_count: int
    platform: str
    local_device_count: int
    inputs: dict  # {role: integrity.file_record} of the input files; {} from older versions
    return_range: list[float] | None = None  # what the run normalised returns by


SEAL = CONFIG_SEAL


def load_saved(directory: Path, allow_unsealed: bool = False) -> SavedRun:
    """The run in ``directory`` to resume, once ``runs.verify_run`` trusts it (its seal,
    unless ``allow_unsealed``; metrics.csv whole and agreeing with summary.json; its
    policies; its input files are checked after the claim, ``check_inputs``), with its
    methods as they were recorded. RunError with one line otherwise."""
    from pngail_jax.analysis.runs import UntrustedRun, verify_run

    path = directory / "config.json"
    if not path.exists():
        raise RunError(f"--resume {directory}: no config.json there")
    try:
        raw = read_json(path, "run config")
        notes = verify_run(
            directory, f"--resume {directory}", allow_unsealed=allow_unsealed, check_inputs=False
        )
    except IntegrityError as error:
        raise RunError(f"--resume {directory}: {error}") from None
    except UntrustedRun as error:
        raise RunError(str(error)) from None
    for note in notes:
        print(f"note: {note}")
    try:
        data = upgrade_saved_config(raw)
        _register_recorded_methods(data)
        try:
            config = RunConfig.from_dict(data)
        except ConfigError as error:
            if error.field != "methods":
                raise
            raise RunError(
                f"--resume {directory}: {error} (a name given to "
                "pngail_jax.adversarial.methods.register must be registered again before the run "
                "resumes)"
            ) from None
        check_methods_unchanged(directory, data["resolved"].get("methods"))
        # The engine that ran goes on running (a run begun on a CPU resumed on a GPU would
        # otherwise switch to MJX, whose state the checkpoint does not hold).
        physics = data["resolved"].get("physics")
        if physics is not None and config.settings.physics is None:
            config = config.replace(settings=config.settings.replace(physics=physics))
        devices = data["provenance"]
        return SavedRun(
            config,
            data["resolved"]["demos_path"],
            devices["device_count"],
            devices["platform"],
            devices["local_device_count"],
            read_run_config(raw).inputs,
            read_run_config(raw).return_range,
        )
    except IntegrityError as error:
        raise RunError(f"--resume {directory}: {error}") from None
    except (TypeError, ValueError, KeyError, AttributeError) as error:
        raise RunError(
            f"--resume {directory}: {path} is damaged or not a run config ({error!r})"
        ) from None


def _register_recorded_methods(data: dict) -> None:
    """Registers again, from the run's record, each method it names that was given to
    ``methods.register`` in the process that began it (a ``package.module:preset`` is imported
    again instead, and checked against its record by ``check_methods_unchanged``)."""
    recorded = data["resolved"].get("methods") or {}
    for name in data.get("methods", ()):
        if isinstance(name, str) and name not in methods.PRESETS and ":" not in name:
            if name in recorded:
                methods.register_recorded(name, recorded[name])
                print(f"note: method {name!r} registered again from the run's config.json")


def check_methods_unchanged(directory: Path, recorded: dict | None) -> None:
    """Refuses to resume a run whose methods now resolve to other presets than it began
    with (an edited ``package.module:preset``); runs from before the record pass."""
    for name, record in (recorded or {}).items():
        now = json.loads(json.dumps(preset_record(name)))
        if now != record:
            raise RunError(
                f"--resume {directory}: method {name!r} is not the preset the run began with "
                f"(then {record}, now {now}); restore it, or start a new run"
            )


def check_inputs(saved: SavedRun, allow_changed: bool) -> None:
    """Refuses to resume on input files that differ from those the run began with."""
    changes = changed_inputs(saved.inputs)
    if not changes:
        return
    if not allow_changed:
        remedy = "restore the file, or pass --allow-changed-inputs to go on anyway"
        raise RunError(changed_inputs_refusal(changes, "cannot resume", "run", remedy))
    listing = "; ".join(changes)
    print(f"WARNING: {listing}; going on (--allow-changed-inputs): the run mixes data sets")


def write_config(out: Path, run: BuiltRun, command: Sequence[str] | None = None) -> None:
    """config.json in the one layout of every run (``runs.run_document``): the RunConfig,
    what it resolved to (with the SHA-256 of every input file, which ``--resume`` checks),
    and provenance."""
    resolved = {
        "demos_path": run.demos_path,
        "inputs": input_files(run.config.demonstrations, run.demos_path),
        "return_range": run.return_range,
        "return_range_source": run.return_range_source,
        "trainer": dataclasses.asdict(run.trainer.config),
        # What each method name resolved to: a resume refuses a changed preset.
        "methods": {name: preset_record(name) for name in run.config.methods},
        # The engine that ran (RunSettings.physics None: chosen from the platform).
        "physics": getattr(run.env, "physics", None),
        "action_scale": run.action_scale,
        "num_demos": run.trainer.num_demos,
        "bsc_eps": run.config.task_bsc_eps,
    }
    document = run_document("sweep", run.config.to_dict(), resolved, provenance(command=command))
    # What the run is created with, apart from the file a user may edit: every resume
    # compares config.json with it (provenance aside) and refuses a change, naming it.
    # Sealed first, so that a config.json never exists without its seal.
    write_sealed(out / "config.json", document, out / SEAL, sealed_part(document))


def already_complete(out: Path) -> bool:
    """Whether ``out``'s summary.json says its run is finished and every output is there (so
    a resume has nothing to do: nothing is recomputed or rewritten)."""
    if not all((out / name).exists() for name in STALE_OUTPUTS):
        return False
    try:
        summary = read_json(out / "summary.json", "run summary")
    except (FileNotFoundError, IntegrityError):
        return False
    return bool(summary.get("complete")) and summary.get("iterations_done") == summary.get(
        "iterations"
    )


STALE_OUTPUTS = (
    "summary.json",
    "summary.md",
    "metrics.csv",
    "curves.png",
    "diagnostics.png",
    "policies",
)


def drop_stale_outputs(out: Path, iterations_done: int) -> None:
    """Removes outputs that claim more iterations than the checkpoint a resume starts from
    (its newer checkpoints were damaged or deleted): they are written again as the run goes."""
    try:
        claimed = read_json(out / "summary.json", "run summary").get("iterations_done", 0)
    except (FileNotFoundError, IntegrityError):
        return
    if claimed <= iterations_done:
        return
    print(
        f"note: the outputs say {claimed} iterations, the checkpoint holds {iterations_done}: "
        "removing the outputs until the run reaches them again"
    )
    for name in STALE_OUTPUTS:
        path = out / name
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)


def as_saved(config: RunConfig, saved: SavedRun) -> RunConfig:
    """``config`` as its run's config.json holds it: absolute paths, and the physics engine
    that ran when the config left it to the platform."""
    config = absolute_paths(config)
    physics = saved.config.settings.physics
    if config.settings.physics is None and physics is not None:
        config = config.replace(settings=config.settings.replace(physics=physics))
    return config


def resume_comparable(config: RunConfig) -> dict:
    """``config.to_dict()`` with its file paths normalised (``a/../b`` is ``b``)."""
    document = config.to_dict()
    for name in ("demos", "conf"):
        if document.get(name) and not str(document[name]).startswith(MINARI_PREFIX):
            document[name] = os.path.normpath(document[name])
    return document


def absolute_paths(config: RunConfig) -> RunConfig:
    """``config`` with its demonstration and confidence files as absolute paths, so that a
    resume from another working directory reads the same files."""
    paths = {}
    if config.demos is not None and not config.demos.startswith(MINARI_PREFIX):
        paths["demos"] = str(Path(config.demos).absolute())
    if config.conf is not None:
        paths["conf"] = str(Path(config.conf).absolute())
    return config.replace(**paths) if paths else config
