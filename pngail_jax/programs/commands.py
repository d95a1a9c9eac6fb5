"""The installed commands (``[project.scripts]`` in pyproject.toml): each runs one program's
``main`` and returns None, so the command's exit status is 0 unless the program exits."""

from __future__ import annotations

PROGRAMS = (
    "sweep", "paper", "train_rl", "make_demos", "classify", "compare_settings", "early_rewards",
    "seeds", "compare", "record", "offline", "agreement",
)  # fmt: skip


def sweep() -> None:
    from pngail_jax.programs import sweep as program

    program.main()


def paper() -> None:
    from pngail_jax.programs import paper as program

    program.main()


def train_rl() -> None:
    from pngail_jax.programs import train_rl as program

    program.main()


def make_demos() -> None:
    from pngail_jax.programs import make_demos as program

    program.main()


def classify() -> None:
    from pngail_jax.programs import classify as program

    program.main()


def compare_settings() -> None:
    from pngail_jax.programs import compare_settings as program

    program.main()


def early_rewards() -> None:
    from pngail_jax.programs import early_rewards as program

    program.main()


def seeds() -> None:
    from pngail_jax.programs import seeds as program

    program.main()


def compare() -> None:
    from pngail_jax.programs import compare as program

    program.main()


def record() -> None:
    from pngail_jax.programs import record as program

    program.main()


def offline() -> None:
    from pngail_jax.programs import offline as program

    program.main()


def agreement() -> None:
    from pngail_jax.programs import agreement as program

    program.main()
