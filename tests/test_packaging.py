"""The package's version is stated once in spirit: pyproject.toml and __version__ agree."""

import tomllib
from pathlib import Path

import pngail_jax

ROOT = Path(__file__).resolve().parent.parent


def test_version_matches_pyproject_and_changelog():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["version"] == pngail_jax.__version__
    assert f"## [{pngail_jax.__version__}]" in (ROOT / "CHANGELOG.md").read_text()
