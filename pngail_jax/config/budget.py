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


# The appendix baselines' own training phases (T-REX's and D-REX's reward fits, D-REX's
# cloning and noisy rollouts, CAIL's rounds, f-IRL's density-ratio discriminator) at one of
# two sizes: "codebase", their codebases' (every result), or "check", small sizes for the check
# and test budgets, which ask whether every method runs, not how well it learns (at the
# codebases' sizes a 20-iteration grid of the appendix methods on one seed took over 25
# minutes on a 2-core CPU; docs/performance.md).
PHASE_SIZES = ("codebase", "check")
CHECK_PHASE_SIZES = {
    # T-REX's and each D-REX member's reward fit: Adam steps (codebases: 10,000) and snippet
    # pairs per step (64). A grid runs every phase its methods need in every cell, so a
    # check grid of the appendix methods fits each of its 8 cells' 4 reward networks.
    "ranking_steps": 100,
    "ranking_pairs_per_step": 16,
    "drex_bc_steps": 500,  # D-REX's cloning (codebase: 50,000)
    "drex_rollouts_per_level": 1,  # noisy episodes per noise level (codebase: 5)
    "cail_rounds": 2,  # CAIL's confidence and discriminator rounds per iteration (10)
    "firl_discriminator_iterations": 50,  # f-IRL's per iteration (codebase: 1,200)
}


def check_phase_sizes(value) -> str:
    """``value`` if it names a size of ``PHASE_SIZES``; ConfigError naming ``phase_sizes``."""
    if value not in PHASE_SIZES:
        fail("phase_sizes", f"must be one of {', '.join(PHASE_SIZES)}, got {value!r}")
    return value
