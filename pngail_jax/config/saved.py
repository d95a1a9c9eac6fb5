"""What a saved ``config.json`` keeps around its ``RunConfig``: the provenance written with it
(where and with what the run ran) and the upgrade of a config written in an older layout.
Both are read by the run record (``jobs.record``) and by ``RunConfig.from_dict``."""

from __future__ import annotations

import dataclasses
import os
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

from pngail_jax.config.learner import upgrade_learner_fields


def upgrade_saved_config(data: dict[str, Any]) -> dict[str, Any]:
    """A sweep's config.json, of any layout, as ``RunConfig.from_dict`` and a resume read
    it: the config's fields beside its ``resolved`` and ``provenance`` sections. Today's
    layout (``analysis.runs.run_document``) has them nested (``sweep_sections``); older
    flat ones are brought up step by step: one written before ``RunConfig`` (flat keys),
    then one from before the learner part (its flat ``learner``, ``fisher``,
    ``fisher_subsample``, ``value_epochs``: ``upgrade_learner_fields``)."""
    return upgrade_learner_fields(_upgrade_flat_config(sweep_sections(data)))


def is_run_document(data: Any) -> bool:
    """Whether a run's config.json (or a record's config) is of ``analysis.runs.run_document``'s
    layout, every run's since issue 74 (marked by its ``family``), rather than one of the two
    before it. (``analysis.runs.read_run_config`` tests the same mark: config/ imports no
    reading module, and the reading layer no run config.)"""
    return isinstance(data, dict) and "family" in data and isinstance(data.get("config"), dict)


def sweep_sections(data: dict[str, Any]) -> dict[str, Any]:
    """A config.json in ``analysis.runs.run_document``'s layout as the config's fields with
    its ``resolved`` and ``provenance`` beside them; a document of an older layout as it is."""
    if not is_run_document(data):
        return data
    return {
        **data["config"],
        "resolved": data.get("resolved") or {},
        "provenance": data.get("provenance") or {},
    }


def _upgrade_flat_config(data: dict[str, Any]) -> dict[str, Any]:
    """A config.json written before ``RunConfig`` (flat keys) in the first ``RunConfig``
    layout."""
    if "classifier_steps" not in data:  # the old layout's mark
        return data
    from pngail_jax.config.settings import REFERENCE_SETTINGS

    needed = ["demos", "platform", "device_count", "local_device_count"]
    if not data.get("settings"):
        needed += ["num_envs", "unroll_length", "eval_every"]
    missing = [key for key in needed if key not in data]
    if missing:
        raise ValueError(
            f"a config.json of the old layout (classifier_steps) lacks key(s) {missing}"
        )

    settings = data.get("settings") or dataclasses.asdict(
        REFERENCE_SETTINGS.replace(
            num_envs=data["num_envs"],
            unroll_length=data["unroll_length"],
            eval_every=data["eval_every"],
        )
    )
    kept = (
        "env methods seeds iterations label_ratios noise_stds seed action_scale num_demos "
        "chunk_iterations fisher fisher_subsample cpu_devices demos conf"
    ).split()
    return {
        **{key: data[key] for key in kept if key in data},
        "settings": settings,
        "classifier": {"num_steps": data["classifier_steps"]},
        "resolved": {"demos_path": data["demos"]},
        "provenance": {
            key: data[key] for key in ("platform", "device_count", "local_device_count")
        },
    }


def provenance(
    argv: list[str] | None = None, program: str | None = None, command=None
) -> dict[str, Any]:
    """Where and with what a run ran: versions, git commit, devices, the command line
    (``command`` as given, the words that start the program included; else ``python -m
    <program> <argv>`` when ``program`` names the module, so that it can be run again as it
    stands)."""
    import jax

    def version(package: str) -> str | None:
        try:
            return metadata.version(package)
        except metadata.PackageNotFoundError:
            return None

    devices = jax.devices()
    return {
        "pngail_jax_version": version("pngail-jax"),
        "git_commit": _git_commit(),
        "python": platform.python_version(),
        "libraries": {
            name: version(name)
            for name in ("jax", "jaxlib", "flax", "optax", "brax", "mujoco", "mujoco-mjx")
        },
        "platform": devices[0].platform,
        "device_kind": devices[0].device_kind,
        # XLA compiles for the CPU it runs on and under XLA_FLAGS: two runs give the same
        # bits only on the same CPU model with the same flags (docs/sweep.md).
        "cpu_model": _cpu_model(),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "device_count": len(devices),
        "local_device_count": len(jax.local_devices()),
        "process_count": jax.process_count(),
        "command_line": list(command)
        if command is not None
        else [
            *(["python", "-m", program] if program else [Path(sys.argv[0]).name]),
            *(sys.argv[1:] if argv is None else argv),
        ],
    }


def _cpu_model() -> str:
    """The host CPU's model name (Linux's /proc/cpuinfo), else what the platform says."""
    try:
        with open("/proc/cpuinfo") as file:
            for line in file:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _git_commit() -> str | None:
    """The checkout's commit (with ``+dirty`` when files differ), or None outside git."""
    root = Path(__file__).resolve().parents[2]  # the checkout: pngail_jax/config/saved.py
    try:
        toplevel = subprocess.run(
            ["git", "rev-parse", "--show-toplevel"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=5,
        )
        if toplevel.returncode != 0 or Path(toplevel.stdout.strip()).resolve() != root:
            return None  # an installed copy, possibly inside another project's checkout
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=5
        )
        if commit.returncode != 0:
            return None
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=5,
        )
        return commit.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None
