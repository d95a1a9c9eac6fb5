"""The installed commands (``[project.scripts]`` in pyproject.toml): each runs one program's
``main`` and returns None, so the command's exit status is 0 unless the program exits."""

from __future__ import annotations

import importlib

PROGRAMS = (
    "sweep", "paper", "train_rl", "make_demos", "classify", "compare_settings", "early_rewards",
    "seeds", "compare",
)  # fmt: skip


def _run(program: str) -> None:
    importlib.import_module(f"pngail_jax.programs.{program}").main()


def sweep() -> None:
    _run("sweep")


def paper() -> None:
    _run("paper")


def train_rl() -> None:
    _run("train_rl")


def make_demos() -> None:
    _run("make_demos")


def classify() -> None:
    _run("classify")


def compare_settings() -> None:
    _run("compare_settings")


def early_rewards() -> None:
    _run("early_rewards")


def seeds() -> None:
    _run("seeds")


def compare() -> None:
    _run("compare")
