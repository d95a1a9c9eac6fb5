"""Demonstrations: validation errors, loaders, round trips and splits."""

from pathlib import Path

import jax
import numpy as np
import pytest
from conftest import authors_data

from pngail_jax import envs
from pngail_jax.demos import (
    DemonstrationError,
    Demonstrations,
    load_demonstrations,
    load_released,
    make_split,
    save_npz,
)

AUTHORS_PENDULUM = authors_data()


def _valid(**overrides):
    rng = np.random.default_rng(0)
    fields = dict(
        observations=rng.normal(size=(10, 3)).astype(np.float32),
        actions=rng.normal(size=(10, 1)).astype(np.float32),
        confidence=rng.uniform(size=10).astype(np.float32),
        labelled=np.arange(10) < 2,
        trajectory_ids=np.repeat([0, 1], 5),
        metadata={"env": "Pendulum-v1", "random_return": -1200.96},
    )
    return {**fields, **overrides}


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (dict(observations=np.zeros(10, np.float32)), r"observations must be 2-D"),
        (dict(actions=np.zeros((9, 1), np.float32)), r"observations has 10 rows but actions has 9"),
        (dict(actions=np.zeros((10, 1), np.int64)), r"actions must be floating point"),
        (dict(observations=np.full((10, 3), np.nan, np.float32)), r"observations contains NaN"),
        (dict(confidence=np.full(10, 1.5, np.float32)), r"confidence must lie in \[0, 1\]"),
        (dict(confidence=np.full(10, np.nan, np.float32)), r"confidence contains NaN"),
        (dict(confidence=np.zeros(7, np.float32)), r"confidence must have shape \(10,\)"),
        (dict(confidence=np.zeros(10, np.int32)), r"confidence must be floating point"),
        (dict(labelled=np.ones(10, np.int32)), r"labelled must be a bool mask"),
        (dict(confidence=None), r"labelled rows given but no confidence"),
        (dict(trajectory_ids=np.zeros(10, np.float32)), r"trajectory_ids must be integers"),
        (
            dict(
                observations=np.zeros((0, 3), np.float32),
                actions=np.zeros((0, 1), np.float32),
                confidence=None,
                labelled=None,
                trajectory_ids=None,
            ),
            r"no demonstration rows",
        ),
    ],
)
def test_validation_errors_name_the_problem(overrides, message):
    with pytest.raises(DemonstrationError, match=message):
        Demonstrations(**_valid(**overrides))


def test_npz_round_trip(tmp_path):
    demos = Demonstrations(**_valid())
    save_npz(tmp_path / "demos.npz", demos)
    loaded = load_demonstrations(tmp_path / "demos.npz")
    for name in ("observations", "actions", "confidence", "labelled", "trajectory_ids"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(demos, name))
    assert loaded.metadata == demos.metadata
    np.testing.assert_array_equal(loaded.inputs[:, 3], demos.actions[:, 0])


def test_npz_version_and_missing_file(tmp_path):
    np.savez(tmp_path / "old.npz", observations=np.zeros((2, 3)), format_version=np.asarray(0))
    with pytest.raises(DemonstrationError, match="unsupported format_version 0"):
        load_demonstrations(tmp_path / "old.npz")
    with pytest.raises(FileNotFoundError, match="demonstrations not found"):
        load_demonstrations(tmp_path / "missing.npz")


def test_released_layout_errors(tmp_path):
    np.save(tmp_path / "Unknown-v0_mixture.npy", np.zeros((4, 5)))
    np.save(tmp_path / "Unknown-v0_mixture_conf.npy", np.zeros((4, 1)))
    with pytest.raises(DemonstrationError, match="unknown environment 'Unknown-v0'"):
        load_released(tmp_path / "Unknown-v0_mixture.npy")
    demos = load_released(tmp_path / "Unknown-v0_mixture.npy", observation_size=3)
    assert demos.observations.shape == (4, 3) and demos.actions.shape == (4, 2)
    with pytest.raises(DemonstrationError, match="cannot be split"):
        load_released(tmp_path / "Unknown-v0_mixture.npy", observation_size=5)
    with pytest.raises(DemonstrationError, match="action_scale must be positive"):
        load_released(tmp_path / "Unknown-v0_mixture.npy", observation_size=3, action_scale=0)


def test_check_env_sizes():
    demos = Demonstrations(**_valid())
    demos.check_env(envs.make("Pendulum-v1"))
    with pytest.raises(DemonstrationError, match="of Pendulum-v1 do not fit Swimmer"):
        demos.check_env(envs.make("Swimmer"))
    unnamed = Demonstrations(**{**_valid(), "metadata": {}})  # sizes are all there is to check
    with pytest.raises(DemonstrationError, match="Swimmer has 8"):
        unnamed.check_env(envs.make("Swimmer"))


@pytest.mark.skipif(
    not (AUTHORS_PENDULUM / "Pendulum-v1_mixture.npy").exists(),
    reason=f"the authors' Pendulum set is not in {AUTHORS_PENDULUM}",
)
def test_released_pendulum_set_loads():
    path = AUTHORS_PENDULUM / "Pendulum-v1_mixture.npy"
    stored = load_released(path, action_scale=1.0)
    scaled = load_released(path)  # the file's known scale: x 2
    assert stored.num_rows == 1000 and stored.observations.shape == (1000, 3)
    assert np.abs(stored.actions).max() <= 1.0  # stored as torque / 2
    np.testing.assert_allclose(scaled.actions, 2 * stored.actions)
    np.testing.assert_allclose(stored.confidence[:200], 1.0)  # the optimal trajectory
    assert 0.3 < stored.confidence[200:].max() < 0.55
    stored.check_env(envs.make("Pendulum-v1"))
    # Its documented layout: five consecutive 200-step episodes, one confidence each.
    np.testing.assert_array_equal(stored.trajectory_ids, np.repeat(np.arange(5), 200))


def _pendulum_file(directory, confidence):
    rows = np.zeros((len(confidence), 4), np.float32)
    np.save(directory / "Pendulum-v1_mixture.npy", rows)
    np.save(directory / "Pendulum-v1_mixture_conf.npy", np.asarray(confidence)[:, None])
    return directory / "Pendulum-v1_mixture.npy"


def test_an_authors_file_carries_the_papers_return_range(tmp_path):
    """A file named as an authors' one carries the paper's Table 3 return range (the random
    and optimal returns its normalised returns use) in its metadata; the table's name from
    before issue 74 still imports, from both places."""
    from pngail_jax.config.released_files import PAPER_NORMALIZERS, PAPER_RETURN_RANGES
    from pngail_jax.demos.released import PAPER_NORMALIZERS as re_exported

    metadata = load_released(_pendulum_file(tmp_path, [1.0] * 200)).metadata
    assert (metadata["random_return"], metadata["optimal_return"]) == (-1200.96, -116.81)
    assert metadata["normalizer_source"] == "paper Table 3"  # the key demos.npz files hold
    assert PAPER_NORMALIZERS is PAPER_RETURN_RANGES and re_exported is PAPER_RETURN_RANGES


def test_released_trajectories_follow_the_documented_layout_or_the_given_length(tmp_path):
    two_episodes = _pendulum_file(tmp_path, np.repeat([1.0, 0.4], 200))
    np.testing.assert_array_equal(load_released(two_episodes).trajectory_ids // 200, 0)
    assert load_released(two_episodes).trajectory_ids[-1] == 1
    explicit = load_released(two_episodes, trajectory_length=100)  # any whole split
    np.testing.assert_array_equal(np.bincount(explicit.trajectory_ids), [100] * 4)
    # Not the documented layout: rows without trajectories by default, an error when asked.
    ragged = _pendulum_file(tmp_path, np.linspace(0, 1, 300))
    assert load_released(ragged).trajectory_ids is None
    with pytest.raises(DemonstrationError, match="300 rows are not whole trajectories of 200"):
        load_released(ragged, trajectory_length=200)
    with pytest.raises(DemonstrationError, match="changes within rows 0-99, so they are not"):
        load_released(ragged, trajectory_length=100)


def test_split_shapes_labels_and_noise():
    confidence = jax.numpy.linspace(0.0, 1.0, 50)
    split = make_split(jax.random.key(0), confidence, traj_size=20, label_ratio=0.2)
    assert split.indices.shape == split.labelled.shape == (20,)
    assert int(split.labelled.sum()) == 4 and bool(split.labelled[:4].all())
    assert len(set(np.asarray(split.indices).tolist())) == 20  # drawn without replacement
    np.testing.assert_array_equal(split.true_confidence, confidence[split.indices])
    np.testing.assert_array_equal(split.confidence, split.true_confidence)
    noisy = make_split(jax.random.key(0), confidence, 20, 0.2, noise_std=0.5)
    np.testing.assert_array_equal(noisy.indices, split.indices)  # same key, same rows
    assert np.all((noisy.confidence >= 0) & (noisy.confidence <= 1))
    assert not np.allclose(noisy.confidence, split.confidence)
    # The label ratio is a value: one compiled split serves a grid of ratios.
    ratios = jax.numpy.array([0.1, 0.2, 0.5])
    grid = jax.jit(jax.vmap(lambda r: make_split(jax.random.key(1), confidence, 20, r)))(ratios)
    np.testing.assert_array_equal(grid.labelled.sum(axis=1), [2, 4, 10])


@pytest.fixture
def minari_dataset(tmp_path, monkeypatch):
    """The id of a local Minari dataset of three random 20-step Pendulum episodes."""
    minari = pytest.importorskip("minari", reason="the optional 'minari' extra is not installed")
    import gymnasium as gym

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    env = minari.DataCollector(gym.make("Pendulum-v1", max_episode_steps=20))
    for episode in range(3):
        env.reset(seed=episode)
        for _ in range(20):
            env.step(env.action_space.sample())
    env.create_dataset(
        dataset_id="pendulum/test-v0",
        algorithm_name="random",
        author="tests",
        author_email="tests@example.invalid",
        code_permalink="tests",
        description="three random Pendulum episodes",
        eval_env="Pendulum-v1",
    )
    return "pendulum/test-v0"


def test_local_minari_dataset_loads(minari_dataset):
    from pngail_jax.demos import load_minari

    demos = load_minari(minari_dataset, confidence=[1.0, 0.5, 0.0])
    assert demos.observations.shape == (60, 3) and demos.actions.shape == (60, 1)
    np.testing.assert_array_equal(np.bincount(demos.trajectory_ids), [20, 20, 20])
    np.testing.assert_array_equal(demos.confidence[::20], [1.0, 0.5, 0.0])
    with pytest.raises(DemonstrationError, match="one value or one per episode"):
        load_minari(minari_dataset, confidence=[1.0, 0.5])
    with pytest.raises(DemonstrationError, match="no local Minari dataset"):
        load_minari("pendulum/missing-v0")


@pytest.mark.parametrize("file_name", ["conf.txt", "conf.npy"])
def test_minari_confidences_from_a_file(minari_dataset, tmp_path, file_name):
    conf_path = tmp_path / file_name
    if file_name.endswith(".npy"):
        np.save(conf_path, np.array([[1.0], [0.5], [0.0]]))  # (N, 1), as the released layout
    else:
        conf_path.write_text("1\n0.5\n0\n")
    demos = load_demonstrations(f"minari:{minari_dataset}", conf_path, action_scale=2.0)
    assert demos.observations.shape == (60, 3)
    np.testing.assert_array_equal(demos.confidence[::20], [1.0, 0.5, 0.0])
    np.testing.assert_array_equal(np.bincount(demos.trajectory_ids), [20, 20, 20])
    unscaled = load_demonstrations(Path(f"minari:{minari_dataset}"))
    assert unscaled.confidence is None
    np.testing.assert_allclose(demos.actions, 2 * unscaled.actions)


def test_minari_confidences_from_an_episode_metadata_field(minari_dataset):
    import minari

    dataset = minari.load_dataset(minari_dataset)
    dataset.storage.update_episode_metadata([{"confidence": c} for c in (0.2, 0.9, 1.0)])
    demos = load_demonstrations(f"minari:{minari_dataset}", confidence_field="confidence")
    np.testing.assert_allclose(demos.confidence[::20], [0.2, 0.9, 1.0])
    with pytest.raises(DemonstrationError, match="episode 0 has no metadata field 'quality'"):
        load_demonstrations(f"minari:{minari_dataset}", confidence_field="quality")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1\n0.5\n", r"conf.txt: 2 confidences for the 3 episodes of Minari dataset"),
        ("1\n1.5\n0\n", r"conf.txt: confidences must lie in \[0, 1\], got values in \[0, 1.5\]"),
        ("1\nnan\n0\n", r"conf.txt: confidences contain NaN"),
        ("1\nhigh\n0\n", r"conf.txt: expected one number per line"),
    ],
)
def test_minari_confidence_file_errors(minari_dataset, tmp_path, text, message):
    conf_path = tmp_path / "conf.txt"
    conf_path.write_text(text)
    with pytest.raises(DemonstrationError, match=message):
        load_demonstrations(f"minari:{minari_dataset}", conf_path)


def test_minari_confidence_sources_are_exclusive(minari_dataset, tmp_path):
    with pytest.raises(DemonstrationError, match="not both"):
        load_demonstrations(f"minari:{minari_dataset}", tmp_path / "c.txt", confidence_field="c")
    with pytest.raises(DemonstrationError, match="confidence_field is for Minari datasets"):
        load_demonstrations(tmp_path / "demos.npz", confidence_field="confidence")
