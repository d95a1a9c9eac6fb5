"""The budget part of a run's config, as plain data: how many seeds from which base seed, and
how many iterations between evaluations, checked once for every job's config (the sweep's
``RunConfig``, ``TrainRLConfig``, ``MakeDemosConfig``) and for ``experiments.train_rl``'s
flags. Imports no JAX."""

from __future__ import annotations

from pngail_jax.config.validation import fail, integer

# jax.random.key takes a seed below 2**63.
SEED_LIMIT = 2**63


def check_seeds(seeds, seed) -> tuple[int, int]:
    """``(seeds, seed)`` as Python ints: at least one seed, a base seed in [0, 2**63)."""
    return integer("seeds", seeds, minimum=1), integer("seed", seed, minimum=0, below=SEED_LIMIT)


def check_eval_interval(iterations: int, eval_every: int, where: str = "settings.eval_every"):
    """An evaluation every ``eval_every`` iterations must end with the run: ConfigError
    naming ``iterations`` otherwise (``where``: what the interval is called, a flag say)."""
    if iterations % eval_every:
        fail(
            "iterations",
            f"({iterations}) must be a multiple of the evaluation interval ({eval_every}, {where})",
        )
