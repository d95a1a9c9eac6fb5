"""End to end: a tiny sweep writes every output; a killed run resumes to the same numbers."""

import csv
import json
import shutil

import numpy as np
import pytest

from experiments import sweep
from pngail_jax.demos import Demonstrations, save_npz

SUMMARY_KEYS = {  # the fields of every earlier summary.json, and the new interval ones
    "final_return_mean",
    "final_return_std",
    "final_normalized_return_mean",
    "final_normalized_return_std",
    "num_seeds",
    "final_normalized_return_iqm",
    "final_normalized_return_ci95",
}


@pytest.fixture(scope="module")
def demos_path(tmp_path_factory):
    rng = np.random.default_rng(0)
    demos = Demonstrations(
        observations=rng.normal(size=(100, 3)).astype(np.float32),
        actions=rng.uniform(-2, 2, size=(100, 1)).astype(np.float32),
        confidence=np.repeat([1.0, 0.4, 0.45, 0.5, 0.35], 20).astype(np.float32),
        metadata={"env": "Pendulum-v1", "random_return": -1200.0, "optimal_return": -150.0},
    )
    path = tmp_path_factory.mktemp("demos") / "demos.npz"
    save_npz(path, demos)
    return path


def tiny_sweep_args(demos_path, out):
    return [
        "--demos", str(demos_path), "--methods", "gail,pngail", "--seeds", "2",
        "--iterations", "4", "--eval-every", "1", "--chunk-iterations", "2",
        "--num-envs", "4", "--unroll-length", "50", "--classifier-steps", "50",
        "--cpu-devices", "1", "--out", str(out),
    ]  # fmt: skip


def read_csv(path):
    with open(path) as file:
        return list(csv.DictReader(file))


def test_sweep_writes_every_output_and_resumes_exactly(demos_path, tmp_path):
    out = tmp_path / "run"
    sweep.main(tiny_sweep_args(demos_path, out))
    for name in ("config.json", "metrics.csv", "curves.png", "summary.md", "summary.json"):
        assert (out / name).stat().st_size > 0, name
    rows = read_csv(out / "metrics.csv")
    assert len(rows) == 2 * 2 * 4  # methods x seeds x iterations
    assert list(rows[0]) == list(sweep_columns())
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary) >= {"methods", "train_env_steps_per_second", "compile_seconds"}
    assert set(summary["methods"]) == {"gail", "pngail"}
    assert set(summary["probability_of_improvement"]) == {"gail"}
    for row in summary["methods"].values():
        assert set(row) >= SUMMARY_KEYS and row["num_seeds"] == 2
        assert np.isfinite(row["final_return_mean"])
    final = [
        float(r["eval_return"]) for r in rows if r["iteration"] == "4" and r["method"] == "gail"
    ]
    np.testing.assert_allclose(
        summary["methods"]["gail"]["final_return_mean"], np.mean(final), rtol=1e-5
    )
    normalized = (np.mean(final) + 1200.0) / 1050.0
    np.testing.assert_allclose(
        summary["methods"]["gail"]["final_normalized_return_mean"], normalized, rtol=1e-5
    )
    assert summary["train_env_steps_per_second"] > 0
    config = json.loads((out / "config.json").read_text())
    assert config["provenance"]["libraries"]["jax"] and config["provenance"]["device_count"] == 1
    assert config["resolved"]["adversarial"]["trpo"]["num_envs"] == 4
    check_exported_policies(out, final)

    # A new run from the saved config is the same run (logging changes no number).
    copy = tmp_path / "copy"
    sweep.main(["--config", str(out / "config.json"), "--out", str(copy), "--log", "tensorboard"])
    assert (copy / "metrics.csv").read_text() == (out / "metrics.csv").read_text()
    assert json.loads((copy / "config.json").read_text())["log"] == ["tensorboard"]
    assert any((copy / "tensorboard").iterdir())

    # A kill after the first chunk: the second chunk's checkpoint and the outputs are lost.
    checkpoints = sorted((out / "checkpoints").iterdir())
    assert [p.name for p in checkpoints] == ["chunk_0001", "chunk_0002"]
    with np.load(checkpoints[-1] / "metrics.npz") as stored:
        uninterrupted = dict(stored)
    shutil.rmtree(checkpoints[-1])
    original = (out / "metrics.csv").read_text()
    (out / "metrics.csv").unlink()
    sweep.main(["--resume", str(out)])
    assert (out / "metrics.csv").read_text() == original
    with np.load(checkpoints[-1] / "metrics.npz") as stored:  # rewritten by the resumed run
        for name, values in uninterrupted.items():
            np.testing.assert_array_equal(stored[name], values, err_msg=name)
    with pytest.raises(SystemExit):  # a second run into the same directory
        sweep.parse_args(tiny_sweep_args(demos_path, out))


def check_exported_policies(out, gail_final_returns):
    """policies/<method>/ loads with load_policy (best seed by default) and drives gymnasium's
    own Pendulum-v1."""
    import gymnasium as gym

    from pngail_jax import load_policy

    assert sorted(p.name for p in (out / "policies").iterdir()) == ["gail", "pngail"]
    best = load_policy(out / "policies" / "gail", verbose=False)
    assert best.seed == int(np.argmax(gail_final_returns))
    np.testing.assert_allclose(best.metadata["final_eval_returns"], gail_final_returns, rtol=1e-5)
    other = load_policy(out / "policies" / "gail", seed=1 - best.seed)
    env = gym.make("Pendulum-v1")
    obs, _ = env.reset(seed=0)
    assert not np.allclose(best(obs), other(obs))  # two different seeds' networks
    total = 0.0
    for _ in range(200):
        action = best(obs)
        assert action.shape == (1,) and -2 <= action[0] <= 2
        obs, reward, terminated, truncated, _ = env.step(action)
        total += reward
    assert truncated and np.isfinite(total)


def sweep_columns():
    from pngail_jax.report import CSV_COLUMNS

    return CSV_COLUMNS


def test_bad_flags_are_named(demos_path, tmp_path, capsys):
    with pytest.raises(SystemExit):
        sweep.parse_args(["--methods", "gail,pu-gail"])
    assert "unknown method(s) ['pu-gail']" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sweep.parse_args(["--env", "CartPole"])
    assert "unknown environment 'CartPole'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sweep.parse_args(["--label-ratio", "0.2,1.5"])
    assert "--label-ratio values must lie in (0, 1)" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sweep.parse_args(["--resume", str(tmp_path), "--seeds", "3"])
    assert "takes no other flags" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sweep.parse_args(["--iterations", "25", "--eval-every", "10"])
    assert "multiple of the evaluation interval (10" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sweep.parse_args(["--env", "Hopper", "--iterations", "60"])  # the table: every 50
    assert "multiple of the evaluation interval (50" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sweep.parse_args(["--env", "Hopper", "--solver", "2"])
    assert "--solver: solver must be 'own', 'fast' or 'I/L'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sweep.parse_args(["--num-envs", "0"])
    assert "--num-envs must be a positive integer" in capsys.readouterr().err


def test_every_flag_has_help_and_its_default():
    parser = sweep.build_parser()
    for action in parser._actions:
        if action.dest != "help":
            assert action.help and "default" in action.help, action.option_strings


def test_presets_and_chunking():
    config = sweep.parse_args(["--preset", "paper", "--seeds", "2"]).config
    assert (config.iterations, config.seeds) == (5000, 2)  # explicit flags beat the preset
    assert sweep.blocks_per_chunk(30, 5) == 5
    assert sweep.blocks_per_chunk(30, 4) == 3
    assert sweep.blocks_per_chunk(7, 5) == 1
