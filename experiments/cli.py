"""Command-line helpers shared by the programs in ``experiments``."""

from __future__ import annotations

import argparse
from collections.abc import Sequence


def known_names(parser: argparse.ArgumentParser, text: str, known: Sequence[str], kind: str):
    """The comma-separated names in ``text`` (a flag's value), in order; exits through
    ``parser.error`` naming the unknown ones (and what is available) when any name is not in
    ``known`` or none is given. ``kind`` names one item, e.g. ``"method"``."""
    names = [name.strip() for name in text.split(",") if name.strip()]
    unknown = [name for name in names if name not in known]
    if unknown or not names:
        parser.error(f"unknown {kind}(s) {unknown}; available: {', '.join(known)}")
    return names
