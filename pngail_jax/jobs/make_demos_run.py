"""A demonstration making's run record and what its resume reads back: ``making_document``
(its ``config.json``, in every run's layout), ``begin_making`` (write it sealed, or check a
resume: ``check_resumable`` refuses one in one line) and ``kept_snapshots`` (the evaluated
policies its first run kept under ``checkpoints/iter_XXXX/``, the candidates phase 2 picks
among).

``jobs.make_demos.make_demonstrations`` writes and reads them; they live apart so that the
job stays one list of steps.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path

import jax
import numpy as np

from pngail_jax.analysis.runs import run_document, sealed_part
from pngail_jax.config.saved import provenance
from pngail_jax.jobs.chunks import resumable_config
from pngail_jax.jobs.errors import RunError
from pngail_jax.rl.learners import learner_hyperparams
from pngail_jax.storage.checkpoint import load_policies
from pngail_jax.storage.integrity import (
    CONFIG_SEAL,
    IntegrityError,
    document_differences,
    write_sealed,
)
from pngail_jax.storage.outputs import Claim

PROGRAM = "make_demos"  # the owner its directories are marked with (pngail_jax.storage.outputs)
DEMOS_FILE = "demos.npz"  # written last: its presence marks a finished run
# The folder of the learner's whole state after every block (jobs.chunks' chunk_NNNN/, the
# last two kept), removed once demos.npz is written; checkpoints/ holds the evaluated
# policies (iter_XXXX/), which the finished run keeps.
TRAINING = "training"

# The fields of ``MakeDemosConfig`` that config.json holds as they are (its parts,
# ``settings`` and ``learner``, as dictionaries).
PLAIN_FIELDS = ("env", "iterations", "seeds", "seed", "ratio", "num_trajectories",
                "intermediate_target", "measure_episodes")  # fmt: skip


def making_document(config, command: Sequence[str] | None = None) -> dict:
    """config.json of a making of ``config`` (a ``jobs.make_demos.MakeDemosConfig``), in every
    run's layout (``analysis.runs.run_document``): ``config``, its fields (the settings and
    the learner whole) and ``argv``, the flags a program was given, which its ``--resume``
    reads back (None from Python); ``resolved``, the environment's options, the rollout and
    the learner's hyperparameters; and ``provenance``."""
    fields = {name: getattr(config, name) for name in PLAIN_FIELDS}
    fields["settings"] = dataclasses.asdict(config.settings)
    fields["learner"] = dataclasses.asdict(config.learner)
    fields["argv"] = None if command is None else list(command)
    hyperparams = learner_hyperparams(config.learner.name)
    resolved = {
        "env_options": config.settings.env_options,
        "rollout": dataclasses.asdict(config.rollout_config),
        "hyperparams": jax.tree.map(lambda x: x.item(), hyperparams).__dict__,
    }
    # provenance's command line: the program's, as it can be run again; from Python, this
    # process's.
    where = (
        provenance()
        if command is None
        else provenance(argv=list(command), program=f"experiments.{PROGRAM}")
    )
    return json.loads(json.dumps(run_document(PROGRAM, fields, resolved, where)))


def begin_making(claim: Claim, document: dict, continue_cut: bool = False) -> None:
    """A new making (``claim``, not resumed) prepares its directory and writes ``document``
    (``making_document``) as its sealed config.json; a resumed one is checked
    (``check_resumable``), under the lock: another resume may have finished it meanwhile.
    ``continue_cut`` (a folder a job keeps for itself, claimed with ``overwrite``): a making of
    the same config cut short there is resumed, anything else replaced."""
    out = claim.directory
    if not claim.resume and continue_cut and is_cut_making(out, document):
        print(f"continuing the making cut short in {out}", flush=True)
        return
    if claim.resume:
        check_resumable(out, document)
        return
    claim.prepare()
    # Sealed first, so that a config.json never exists without its seal.
    write_sealed(out / "config.json", document, out / CONFIG_SEAL, sealed_part(document))


def check_resumable(out: Path, document: dict) -> None:
    """Refuses (``RunError``, one line) to resume a directory without a making, a finished
    one (its demos.npz written), one without its seal or whose config.json was changed, or
    one whose config differs from ``document`` (what the resumed config gives)."""
    saved = resumable_config(out, PROGRAM, DEMOS_FILE)
    changes = document_differences(sealed_part(saved), sealed_part(document))
    if changes:
        listed = "; ".join(changes[:5])
        raise RunError(f"cannot resume {out}: these flags give another run ({listed})")


def is_cut_making(out: Path, document: dict) -> bool:
    """Whether ``out`` holds a making of ``document``'s config (``making_document``) cut short,
    which a resume can continue (``check_resumable`` would accept it)."""
    if not (out / "config.json").exists() or (out / DEMOS_FILE).exists():
        return False
    try:
        check_resumable(out, document)
    except RunError:
        return False
    return True


def kept_snapshots(out: Path, eval_every: int, before: int) -> list[tuple]:
    """The evaluated policies a making kept under ``out/checkpoints/iter_XXXX/`` for every
    evaluation before iteration ``before`` (every ``eval_every`` iterations), in the order
    it kept them (by iteration, then seed): ``(iteration, seed, policy_params, normalizer,
    eval_return)`` each, the fields of ``jobs.make_demos.Checkpoint``. A folder missing or
    damaged is refused in one line: the candidates would not be the uninterrupted run's."""
    snapshots = []
    for iteration in range(eval_every, before, eval_every):
        folder = out / "checkpoints" / f"iter_{iteration:04d}"
        try:
            params, normalizer, returns = load_policies(folder)
        except (OSError, ValueError, IntegrityError) as error:
            raise RunError(
                f"cannot resume {out}: the policies of iteration {iteration} cannot be read "
                f"({error}); start a new making"
            ) from None
        for seed, eval_return in enumerate(returns):
            pick = jax.tree.map(lambda x, s=seed: np.asarray(x[s]), (params, normalizer))
            snapshots.append((iteration, seed, *pick, float(eval_return)))
    return snapshots
