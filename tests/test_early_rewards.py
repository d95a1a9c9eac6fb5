"""A tiny run of experiments.early_rewards, so the diagnostic cannot drift from the library."""

import json
import math

import pytest
from conftest import authors_data

from pngail_jax.jobs.early_rewards import EarlyRewardsConfig
from pngail_jax.jobs.early_rewards import early_rewards as early_rewards_job
from pngail_jax.jobs.errors import RunError
from pngail_jax.programs import early_rewards

PENDULUM = authors_data() / "Pendulum-v1_mixture.npy"


@pytest.mark.skipif(not PENDULUM.exists(), reason=f"the authors' Pendulum set is not at {PENDULUM}")
def test_early_rewards_reads_every_variant_at_every_reading(tmp_path):
    out = tmp_path / "early.json"
    flags = ["--demos", str(PENDULUM), "--seeds", "1", "--iterations", "2", "--every", "1"]
    early_rewards.main([*flags, "--classifier-steps", "10", "--out", str(out)])
    readings = json.loads(out.read_text())["readings"]
    assert [(r["iteration"], r["variant"]) for r in readings] == [
        (iteration, label) for iteration in (1, 2) for label, _, _ in early_rewards.VARIANTS
    ]
    assert all(
        math.isfinite(value) for r in readings for value in r.values() if value != r["variant"]
    )
    with pytest.raises(SystemExit, match=f"^early_rewards: {out} exists: choose another output"):
        early_rewards.main([*flags, "--out", str(out)])  # never over an existing file


def test_the_job_refuses_bad_settings_and_an_existing_file_before_any_work(tmp_path):
    with pytest.raises(ValueError, match="iterations >= every"):
        EarlyRewardsConfig(str(PENDULUM), iterations=5, every=10)
    with pytest.raises(ValueError, match="classifier_steps"):
        EarlyRewardsConfig(str(PENDULUM), classifier_steps=0)
    with pytest.raises(SystemExit, match=r"iterations \(15\) must be a multiple of every \(10\)"):
        early_rewards.main(["--demos", str(PENDULUM), "--iterations", "15", "--every", "10"])
    existing = tmp_path / "early.json"
    existing.write_text("{}")
    with pytest.raises(RunError, match="exists"):
        early_rewards_job(EarlyRewardsConfig(str(PENDULUM)), existing)
    assert existing.read_text() == "{}"
    with pytest.raises(RunError, match="demonstrations"):
        early_rewards_job(EarlyRewardsConfig(str(tmp_path / "missing.npy")), tmp_path / "a.json")
