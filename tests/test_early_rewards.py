"""A tiny run of experiments.early_rewards, so the diagnostic cannot drift from the library."""

import json
import math

import pytest
from conftest import authors_data

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
    with pytest.raises(SystemExit):  # never over an existing file
        early_rewards.main([*flags, "--out", str(out)])
