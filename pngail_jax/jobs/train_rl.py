"""``train_rl(config, out)``: TRPO (or PPO) on an environment's true reward, several seeds in one
compiled program, with progress, checkpoints it resumes from, and its outputs:
``config.json``, ``metrics.csv`` (one row per seed and iteration), ``learning_curve.png`` and
the policies (``policy.json`` + ``policy_params/``), which ``pngail_jax.load_policy(out)``
loads without this code.

    from pngail_jax.jobs.train_rl import TrainRLConfig, train_rl

    train_rl(TrainRLConfig(env="Pendulum-v1", iterations=100, seeds=3), "runs/trpo")
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import time
from collections.abc import Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from pngail_jax.analysis.report import write_seed_metrics_csv
from pngail_jax.analysis.runs import run_document, sealed_part
from pngail_jax.config import settings as env_settings
from pngail_jax.config.learner import LearnerConfig
from pngail_jax.config.saved import is_run_document, provenance
from pngail_jax.config.training import check_training
from pngail_jax.jobs.chunks import nanmean, resumable_config
from pngail_jax.jobs.errors import RunError, refusals
from pngail_jax.jobs.train_seeds import train_seeds
from pngail_jax.rl import PolicyTrainer, RolloutConfig, TRPOConfig, TRPOHyperparams
from pngail_jax.rl.learners import learner_hyperparams, make_learner
from pngail_jax.storage.checkpoint import save_trpo_policies
from pngail_jax.storage.integrity import (
    CONFIG_SEAL,
    atomic_path,
    document_differences,
    write_manifest,
    write_sealed,
)
from pngail_jax.storage.outputs import claimed

PROGRAM = "train_rl"  # the owner its directories are marked with (pngail_jax.storage.outputs)
# metrics.csv's columns after seed and iteration, by learner.
METRIC_COLUMNS = {
    "trpo": (
        "env_steps", "eval/return", "train/episode_return", "trpo/kl", "trpo/entropy",
        "trpo/accepted", "value/loss",
    ),
    "ppo": (
        "env_steps", "eval/return", "train/episode_return", "ppo/kl", "ppo/entropy",
        "ppo/clip_fraction", "value/loss",
    ),
}  # fmt: skip


@dataclasses.dataclass(frozen=True)
class TrainRLConfig:
    """A TRPO (or, ``learner="ppo"``, PPO) run on the true reward. ``settings`` None: the
    task's row of ``pngail_jax.config.settings``. ``learner``: the policy learner's part
    (``config.learner.LearnerConfig``: its name and each learner's static settings; a name
    alone is that learner at its defaults). ``truncation_as_terminal``: the reference's GAE,
    which does not bootstrap through time limits."""

    env: str = "Pendulum-v1"
    iterations: int = 100
    seeds: int = 3
    seed: int = 0
    truncation_as_terminal: bool = False
    settings: env_settings.RunSettings | None = None
    learner: LearnerConfig = LearnerConfig()

    def __post_init__(self):
        check_training(self)  # env, settings, the budget and the learner, as every job's

    @property
    def rollout_config(self) -> RolloutConfig:
        return self.settings.rollout_config(self.iterations)

    @property
    def hyperparams(self) -> TRPOHyperparams:
        return learner_hyperparams(
            self.learner.name, bootstrap_truncation=not self.truncation_as_terminal
        )

    def trainer(self, env) -> PolicyTrainer:
        """The trainer of this run in ``env`` (its learner on the true reward)."""
        config = self.rollout_config
        learner = make_learner(self.learner, config, env)
        return PolicyTrainer(config, env, learner=learner)

    def document(self, command: Sequence[str] | None = None) -> dict:
        """config.json's content, in every run's layout (``analysis.runs.run_document``):
        ``config``, what the run was asked (its fields, the learner part whole, and
        ``argv``: the flags a program was given, which its ``--resume`` reads back; None
        from Python), ``resolved``, what that gave when the run began (the environment's
        options, the rollout, the learner's hyperparameters), and ``provenance``."""
        config = {
            "env": self.env,
            "iterations": self.iterations,
            "seeds": self.seeds,
            "seed": self.seed,
            "truncation_as_terminal": self.truncation_as_terminal,
            "settings": dataclasses.asdict(self.settings),
            "learner": dataclasses.asdict(self.learner),
            "argv": None if command is None else list(command),
        }
        resolved = {
            "env_options": self.settings.env_options,
            "rollout": dataclasses.asdict(self.rollout_config),
            "hyperparams": jax.tree.map(lambda x: x.item(), self.hyperparams).__dict__,
        }
        # provenance's command line: the program's, as it can be run again (the flags alone
        # would not run); from Python, this process's.
        where = (
            provenance()
            if command is None
            else provenance(argv=list(command), program="experiments.train_rl")
        )
        return json.loads(json.dumps(run_document(PROGRAM, config, resolved, where)))


def train_rl(
    config: TrainRLConfig,
    out,
    *,
    overwrite: bool = False,
    resume: bool = False,
    command: Sequence[str] | None = None,
) -> Path:
    """Trains ``config`` into ``out`` (new, empty, or with ``overwrite`` a run of train_rl) and
    returns ``out``. ``resume``: continue the interrupted run in ``out``, which must have
    been begun with the same config (and ``command``). A stop asked for by a signal handler
    ends at the next block's checkpoint. Raises ``RunError`` with one line."""
    out = Path(out)
    with refusals(), claimed(out, PROGRAM, overwrite=overwrite, resume=resume) as claim:
        try:
            env = env_settings.make_env(config.env, config.settings, cells=config.seeds)
        except ValueError as error:  # e.g. a custom factory that raised or returned no Env
            raise RunError(f"environment: {error}") from None
        document = config.document(command)
        if resume:  # checked under the lock: another resume may have finished it meanwhile
            check_resumable(out, document)
        else:
            claim.prepare()
            # Sealed first, so that a config.json never exists without its seal.
            write_sealed(out / "config.json", document, out / CONFIG_SEAL, sealed_part(document))
        _train(config, env, out)
    return out


def upgrade_document(document: dict) -> dict:
    """A train_rl config.json of the flat layout before ``runs.run_document`` in its last form
    (that form unchanged): the rollout's settings moved from "trpo" (which held them beside
    TRPO's, whichever learner ran) to "rollout"; a TRPO section lacking a field added since
    (``num_value_epochs``) has its default. A document of today's layout as it is."""
    if is_run_document(document):
        return document
    upgraded, old = document, document.get("trpo")
    if isinstance(old, dict) and "num_envs" in old:
        shared = {field.name for field in dataclasses.fields(RolloutConfig)}
        upgraded = {key: value for key, value in document.items() if key != "trpo"}
        upgraded["rollout"] = {key: value for key, value in old.items() if key in shared}
        if document.get("learner", "trpo") == "trpo":
            upgraded["trpo"] = {key: value for key, value in old.items() if key not in shared}
    trpo = upgraded.get("trpo")
    defaults = dataclasses.asdict(TRPOConfig())
    if isinstance(trpo, dict) and not defaults.keys() <= trpo.keys():
        upgraded = {**upgraded, "trpo": {**defaults, **trpo}}
    return upgraded


def flat_document(document: dict) -> dict:
    """A train_rl config.json of any layout in the keys of the flat one (every layout holds
    them): ``env``, ``env_options``, ``settings``, ``seeds``, ``seed``, ``learner`` (the
    name), ``rollout``, the running learner's settings under its name, ``hyperparams`` and
    ``argv``. What ``compare_settings`` reads of an arm, and what a resume of a run begun
    in a flat layout compares (that layout held no more)."""
    document = upgrade_document(document)
    if not is_run_document(document):
        return document
    config, resolved = (
        part if isinstance(part, dict) else {}
        for part in (document.get("config"), document.get("resolved"))
    )  # a hand-edited part that is no object reads as empty (the seal names the change)
    learner = config.get("learner") if isinstance(config.get("learner"), dict) else {}
    name = learner.get("name") if isinstance(learner.get("name"), str) else None
    flat = {key: config.get(key) for key in ("env", "settings", "seeds", "seed", "argv")}
    flat.update({key: resolved.get(key) for key in ("env_options", "rollout", "hyperparams")})
    return {**flat, "learner": name, str(name): learner.get(name)}


def _sealed(document: dict) -> dict:
    """What a train_rl config.json's seal covers: in ``runs.run_document``'s layout all but
    its provenance (``runs.sealed_part``), in the flat ones before it the whole file."""
    return sealed_part(document) if is_run_document(document) else document


def check_resumable(out: Path, document: dict) -> None:
    """Refuses to resume a finished run, a run without its seal, or one whose flags or
    config.json differ from the config it was sealed with when it began (``document``: what
    the resumed flags give, in today's layout). A run begun in a flat layout is compared in
    that layout's keys (``flat_document``); its config.json is never rewritten."""
    saved = resumable_config(out, PROGRAM, "policy.json", part=_sealed)
    if is_run_document(saved):
        changes = document_differences(sealed_part(saved), sealed_part(document))
    else:
        changes = document_differences(upgrade_document(saved), flat_document(document))
    if changes:
        listed = "; ".join(changes[:5])
        raise RunError(f"cannot resume {out}: these flags give another run ({listed})")


def _train(config: TrainRLConfig, env, out: Path) -> None:
    rollout = config.rollout_config
    trainer = config.trainer(env)
    learner = config.learner.name.upper()
    hyperparams = jax.tree.map(
        lambda x: jnp.broadcast_to(x, (config.seeds, *x.shape)), config.hyperparams
    )
    keys = jax.random.split(jax.random.key(config.seed), config.seeds)
    print(
        f"{learner} on {config.env}: {config.seeds} seeds x {config.iterations} iterations x "
        f"{rollout.batch_size} steps ({env_settings.describe(config.settings)}) -> {out}",
        flush=True,
    )
    start = time.perf_counter()
    state, metrics = train_seeds(trainer, hyperparams, keys, checkpoints=out / "checkpoints")
    final_returns = metrics["eval/return"][:, -1]
    write_seed_metrics_csv(out / "metrics.csv", metrics, METRIC_COLUMNS[config.learner.name])
    plot_learning_curve(
        out / "learning_curve.png", metrics, f"{learner} on {config.env} ({config.seeds} seeds)"
    )
    save_trpo_policies(
        out, env, rollout, state, final_returns, {"env_options": config.settings.env_options}
    )
    # The run is complete: its checkpoints go, and the digests list what stays.
    shutil.rmtree(out / "checkpoints", ignore_errors=True)
    write_manifest(out)
    print(
        f"done in {time.perf_counter() - start:.0f} s; final deterministic returns "
        f"[{', '.join(f'{r:.1f}' for r in final_returns)}] (mean {final_returns.mean():.1f}); "
        f"wrote {out}/{{config.json,metrics.csv,learning_curve.png,policy.json}}"
    )


def plot_learning_curve(path: Path, metrics: dict[str, np.ndarray], title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(7, 4.5))
    steps = metrics["env_steps"][0]
    evaluated = ~np.isnan(metrics["eval/return"][0])
    for seed, returns in enumerate(metrics["eval/return"]):
        axis.plot(
            steps[evaluated],
            returns[evaluated],
            color="tab:blue",
            alpha=0.35,
            lw=1,
            label="seeds (deterministic eval)" if seed == 0 else None,
        )
    mean = metrics["eval/return"][:, evaluated].mean(axis=0)
    axis.plot(steps[evaluated], mean, color="black", lw=2, marker="o", ms=3, label="mean")
    train_mean = nanmean(metrics["train/episode_return"], axis=0)
    # Iterations where no episode ended are NaN (a 1000-step episode ends every fifth
    # 200-step iteration): joined over them, or matplotlib draws isolated, invisible points.
    ended = np.isfinite(train_mean)
    axis.plot(
        steps[ended], train_mean[ended], color="tab:orange", lw=1, label="training episodes (mean)"
    )
    axis.set(xlabel="environment steps", ylabel="episode return", title=title)
    axis.grid(alpha=0.3)
    axis.legend()
    figure.tight_layout()
    with atomic_path(path) as temporary:
        figure.savefig(temporary, dpi=120)
    plt.close(figure)
