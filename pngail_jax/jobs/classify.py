"""``classify(config)``: Table 1, how well SC and BSC recover hidden confidences, every
classifier x seed in one program; and Table 5, the variance of each trained classifier's BSC
risk. Reads raw [s, a] rows (no environment needed), draws per seed a split of
``num_demos`` rows with ``label_ratio`` of them labelled (only rows a file's ``labelled``
mask allows), trains each classifier and reports MAE / RMSE over the unlabelled rows (mean
and population std over seeds), against the confidences before noise.

    from pngail_jax.jobs.classify import ClassifyConfig, classify

    summary = classify(ClassifyConfig(demos="data/released/Pendulum-v1_mixture.npy"))
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import jax
import jax.numpy as jnp

from pngail_jax import envs
from pngail_jax.analysis.report import json_safe
from pngail_jax.confidence import ClassifierConfig, ClassifierSpec, split_and_train
from pngail_jax.config import validation
from pngail_jax.demos import (
    DemonstrationError,
    Demonstrations,
    action_scale_note,
    load_demonstrations,
)
from pngail_jax.jobs.errors import RunError
from pngail_jax.storage.integrity import write_json

METHODS = {"sc": ClassifierSpec.sc, "bsc": ClassifierSpec.bsc}


@dataclasses.dataclass(frozen=True)
class ClassifyConfig:
    """The demonstrations (``demos``, ``conf``, ``action_scale`` as the sweep reads them;
    ``env`` splits a file of rows that is not an authors' one), the split (``num_demos`` rows
    per seed, None: all; ``label_ratio`` labelled; confidence ``noise``) and the classifiers'
    training (the authors' batch: ``batch_size`` labelled rows per step and n_u / n_c
    unlabelled per labelled one)."""

    demos: str
    conf: str | None = None
    action_scale: float | None = None
    env: str | None = None
    num_demos: int | None = None
    label_ratio: float = 0.2
    noise: float = 0.0
    classifiers: tuple[str, ...] = ("sc", "bsc")
    seeds: int = 5
    seed: int = 0
    classifier_steps: int = 25_000
    batch_size: int = 1
    bsc_eps: float = 0.01

    def __post_init__(self):
        object.__setattr__(self, "classifiers", tuple(self.classifiers))
        unknown = [name for name in self.classifiers if name not in METHODS]
        if unknown or not self.classifiers:
            validation.fail("classifiers", f"must be among {', '.join(METHODS)}, got "
                            f"{', '.join(self.classifiers) or 'none'}")  # fmt: skip
        if not 0 < self.label_ratio < 1:  # also refuses nan
            validation.fail("label_ratio", f"must be in (0, 1), got {self.label_ratio}")
        for name in ("seeds", "classifier_steps", "batch_size"):
            validation.integer(name, getattr(self, name), 1)
        if self.num_demos is not None:
            validation.integer("num_demos", self.num_demos, 2)
        for name, value, positive in (
            ("noise", self.noise, False),
            ("bsc_eps", self.bsc_eps, True),
            ("action_scale", 1.0 if self.action_scale is None else self.action_scale, True),
        ):
            if not (math.isfinite(value) and (value > 0 if positive else value >= 0)):
                validation.fail(name, f"must be a finite number {'> 0' if positive else '>= 0'}"
                                f", got {value}")  # fmt: skip


def classify(config: ClassifyConfig, json_path=None) -> dict:
    """Trains the classifiers of ``config`` (every seed of each in one program), prints their
    errors (Table 1) and BSC risk variances (Table 5), writes them to ``json_path`` when
    given, and returns the summary. Raises ``RunError`` with one line."""
    demos = load(config)
    traj_size, num_labelled = split_sizes(config, demos)
    classifier = classifier_config(config, traj_size, num_labelled)
    specs = [METHODS[m]() if m == "sc" else METHODS[m](config.bsc_eps) for m in config.classifiers]
    mask_note = (
        ""
        if demos.labelled is None
        else f" (at most, from the {int(demos.labelled.sum())} rows the file's mask allows)"
    )
    print(
        f"{demos.num_rows} rows from {config.demos}; {traj_size} per seed, {num_labelled} "
        f"labelled{mask_note}; {len(specs)} classifier(s) x {config.seeds} seeds x "
        f"{config.classifier_steps} steps of {classifier.labelled_batch_size} + "
        f"{classifier.unlabelled_batch_size} rows",
        flush=True,
    )
    start = time.perf_counter()
    results = train_all(config, demos, classifier, specs, traj_size)
    seconds = time.perf_counter() - start
    summary = error_table(config, results)
    variance_table(config, results, summary)
    print(
        f"\n{len(specs) * config.seeds} classifier runs in {seconds:.1f} s (one program, "
        "compilation included)"
    )
    if json_path is not None:
        json_path = Path(json_path)
        json_path.parent.mkdir(parents=True, exist_ok=True)
        write_json(json_path, json_safe(summary))
        print(f"wrote {json_path}")
    return summary


def load(config: ClassifyConfig) -> Demonstrations:
    """The demonstrations, which must carry confidences, with the note on an applied action
    scale; a bad file is a ``RunError`` naming it."""
    sizes = {}
    try:
        if config.env is not None:
            try:
                env = envs.make(config.env)
            except ValueError as error:
                raise DemonstrationError(f"--env: {error}") from None
            sizes = {"observation_size": env.observation_size, "action_size": env.action_size}
        demos = load_demonstrations(config.demos, config.conf, config.action_scale, **sizes)
        if demos.confidence is None:
            raise DemonstrationError(f"{config.demos}: these demonstrations carry no confidence")
    except (DemonstrationError, FileNotFoundError) as error:
        raise RunError(f"classify: {error}") from None
    if action_scale_note(demos):
        print(action_scale_note(demos))
    return demos


def split_sizes(config: ClassifyConfig, demos) -> tuple[int, int]:
    """Rows per seed's split and how many of them are labelled, checked against the file."""
    traj_size = demos.num_rows if config.num_demos is None else config.num_demos
    if not 2 <= traj_size <= demos.num_rows:
        raise RunError(f"--num-demos must be in [2, {demos.num_rows}], got {traj_size}")
    num_labelled = round(config.label_ratio * traj_size)
    if not 1 <= num_labelled < traj_size:
        raise RunError(
            f"label ratio {config.label_ratio} of {traj_size} rows leaves "
            f"{num_labelled} labelled: need at least one of each kind"
        )
    try:
        check_labelled_mask(demos, config.demos, num_labelled)
    except DemonstrationError as error:
        raise RunError(f"classify: {error}") from None
    return traj_size, num_labelled


def classifier_config(config: ClassifyConfig, traj_size: int, num_labelled: int):
    """The authors' batch: per labelled row, int(n_u / n_c) unlabelled rows."""
    authors = ClassifierConfig(
        num_steps=config.classifier_steps, labelled_batch_size=config.batch_size
    )
    return dataclasses.replace(
        authors, unlabelled_batch_size=authors.unlabelled_rows_per_step(traj_size, num_labelled)
    )


def check_labelled_mask(demos: Demonstrations, path: Path, num_labelled: int) -> None:
    """Raises ``DemonstrationError`` when the file's ``labelled`` mask allows fewer rows than
    the ``num_labelled`` asked for (the split labels only rows the mask allows)."""
    if demos.labelled is not None and demos.labelled.sum() < num_labelled:
        raise DemonstrationError(
            f"{path}: its labelled mask allows only {int(demos.labelled.sum())} of "
            f"{demos.num_rows} rows to be labelled, fewer than the {num_labelled} asked for "
            "(lower --label-ratio or --num-demos)"
        )


def train_all(job: ClassifyConfig, demos, config: ClassifierConfig, specs, traj_size: int) -> dict:
    """Every classifier x seed as one ``jit(vmap)``; results with a leading [specs * seeds]
    axis, classifier-major."""
    stacked = jax.tree.map(lambda *x: jnp.repeat(jnp.stack(x), job.seeds, axis=0), *specs)
    keys = jnp.tile(jax.random.split(jax.random.key(job.seed), job.seeds), len(specs))

    def run(spec, key):
        return split_and_train(
            config,
            spec,
            jnp.asarray(demos.inputs),
            jnp.asarray(demos.confidence),
            traj_size,
            job.label_ratio,
            job.noise,
            key,
            allowed=None if demos.labelled is None else jnp.asarray(demos.labelled),
        )

    return jax.device_get(jax.jit(jax.vmap(run))(stacked, keys))


def error_table(job: ClassifyConfig, results) -> dict:
    """Prints each classifier's MAE and RMSE on D_u over seeds; returns them by classifier."""
    summary = {}
    print("\n| method | MAE | RMSE | BSC clip active |\n|---|---|---|---|")
    for index, method in enumerate(job.classifiers):
        rows = slice(index * job.seeds, (index + 1) * job.seeds)
        mae, rmse = results["mae"][rows], results["rmse"][rows]
        summary[method] = {
            "mae_mean": float(mae.mean()),
            "mae_std": float(mae.std()),
            "rmse_mean": float(rmse.mean()),
            "rmse_std": float(rmse.std()),
        }
        clip = f"{results['clip_active'][rows].mean():.0%}" if method == "bsc" else "-"
        print(
            f"| {method.upper()} | {mae.mean():.3f} ± {mae.std():.3f} | "
            f"{rmse.mean():.3f} ± {rmse.std():.3f} | {clip} |"
        )
    return summary


def variance_table(job: ClassifyConfig, results, summary: dict) -> None:
    """Prints Table 5 (the BSC risk's variance with and without alpha, beta) and adds it to
    ``summary``."""
    print(
        "\nTable 5, variance of the empirical BSC risk of each trained classifier "
        "(bootstrap over D_c and D_u; mean +- std over seeds):\n"
        "| method | alpha = beta = 0 (origin) | alpha = beta = n_u / (n_c + n_u) |\n"
        "|---|---|---|"
    )
    for index, method in enumerate(job.classifiers):
        rows = slice(index * job.seeds, (index + 1) * job.seeds)
        origin, balanced = results["variance_origin"][rows], results["variance_balanced"][rows]
        summary[method]["variance_origin"] = float(origin.mean())
        summary[method]["variance_balanced"] = float(balanced.mean())
        print(
            f"| {method.upper()} | {origin.mean():.2e} ± {origin.std():.1e} | "
            f"{balanced.mean():.2e} ± {balanced.std():.1e} |"
        )
