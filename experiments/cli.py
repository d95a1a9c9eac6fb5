"""Command-line helpers shared by the programs in ``experiments``."""

from __future__ import annotations

import argparse
from collections.abc import Sequence


class HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Every flag's help ends with its default, unless the help already names it; epilogs and
    descriptions keep their line breaks."""

    def _get_help_string(self, action):
        help_text = action.help or ""
        if "default" in help_text or action.required:
            return help_text
        return super()._get_help_string(action)


def known_names(parser: argparse.ArgumentParser, text: str, known: Sequence[str], kind: str):
    """The comma-separated names in ``text`` (a flag's value), in order; exits through
    ``parser.error`` naming the unknown ones (and what is available) when any name is not in
    ``known`` or none is given. ``kind`` names one item, e.g. ``"method"``."""
    names = [name.strip() for name in text.split(",") if name.strip()]
    unknown = [name for name in names if name not in known]
    if unknown or not names:
        parser.error(f"unknown {kind}(s) {unknown}; available: {', '.join(known)}")
    return names


def comma_floats(parser: argparse.ArgumentParser, flag: str, text: str | None):
    """The comma-separated numbers of a flag's value as a tuple (None when not given); exits
    through ``parser.error`` naming ``flag`` when one is not a number."""
    if text is None:
        return None
    try:
        return tuple(float(x) for x in str(text).split(","))
    except ValueError:
        parser.error(f"{flag} must be comma-separated numbers, got {text!r}")


ENV_HELP = (
    "a built-in (Pendulum-v1, Ant, HalfCheetah, Hopper, Walker2d, Swimmer), a registered name, "
    "or package.module:factory (docs/environments.md)"
)


def check_env(parser: argparse.ArgumentParser, name: str) -> str:
    """``name`` when ``pngail_jax.envs.make`` knows it; else exits through ``parser.error``
    naming what is available."""
    from pngail_jax import envs

    try:
        envs.check_name(name)
    except ValueError as error:
        parser.error(str(error))
    return name


def check_positive(parser: argparse.ArgumentParser, args, names) -> None:
    """Exits through ``parser.error`` naming the first flag (``args`` attribute) below 1."""
    for name in names:
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be positive")
