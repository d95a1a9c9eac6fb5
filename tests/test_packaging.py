"""The package's version is stated once in spirit: pyproject.toml and __version__ agree."""

import tomllib
from pathlib import Path

import pytest

import pngail_jax

ROOT = Path(__file__).resolve().parent.parent


def test_version_matches_pyproject_and_changelog():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["version"] == pngail_jax.__version__
    assert f"## [{pngail_jax.__version__}]" in (ROOT / "CHANGELOG.md").read_text()


def test_the_old_module_name_still_imports_with_a_warning():
    import importlib
    import sys

    sys.modules.pop("pngail_jax.train", None)
    with pytest.warns(DeprecationWarning, match="pngail_jax.adversarial.trainer"):
        old = importlib.import_module("pngail_jax.train")
    from pngail_jax.adversarial.trainer import AdversarialHyperparams, AdversarialTrainer

    assert (
        old.Hyperparams is AdversarialHyperparams and old.AdversarialTrainer is AdversarialTrainer
    )


def test_the_runners_old_names_still_import_with_a_warning():
    import importlib
    import sys

    from pngail_jax.jobs import build, chunks, record, sweep

    sys.modules.pop("pngail_jax.runner", None)
    with pytest.warns(DeprecationWarning, match="pngail_jax.runner is now pngail_jax.jobs"):
        old = importlib.import_module("pngail_jax.runner")
    assert old.run is sweep.run and old.build is build.build_run
    assert old.load_saved is record.load_saved and old.train_seeds.__module__.endswith("seeds")
    assert old.intact_checkpoint is chunks.intact_checkpoint
