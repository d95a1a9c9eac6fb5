"""experiments.make_demos end to end on a tiny budget, and the rollout helpers."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pngail_jax
from pngail_jax import envs
from pngail_jax.demos import load_demonstrations
from pngail_jax.demos.generate import normalized_return, rollout_episodes
from pngail_jax.programs import make_demos
from pngail_jax.storage import outputs


def test_make_demos_tiny_pendulum(tmp_path, capsys):
    path = make_demos.main(
        [
            "--env",
            "Pendulum-v1",
            "--out",
            str(tmp_path),
            "--iterations",
            "4",
            "--eval-every",
            "2",
            "--seeds",
            "2",
            "--num-envs",
            "4",
            "--unroll-length",
            "50",
            "--num-trajectories",
            "5",
            "--measure-episodes",
            "4",
        ]
    )
    # Written through temporary siblings that were renamed: none is left behind.
    names = [".config.sealed.json", ".pngail-outputs.json", ".pngail-run.json", "checkpoints",
             "config.json", "demos.npz", "normalizer.json"]  # fmt: skip
    assert sorted(p.name for p in tmp_path.iterdir()) == names
    # Finished work is not replaced by a second run without --overwrite.
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        make_demos.parse_args(["--out", str(tmp_path)])
    assert (
        f"--out {tmp_path} already holds a run of experiments.make_demos: --resume {tmp_path} "
        "to continue it, pass --overwrite to replace it"
    ) in capsys.readouterr().err
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        demos = load_demonstrations(path)
    assert demos.num_rows == 5 * 200 and demos.observations.shape[1] == 3
    assert np.all((demos.confidence >= 0) & (demos.confidence <= 1))
    assert np.all(np.abs(demos.actions) <= 2.0)
    np.testing.assert_array_equal(np.bincount(demos.trajectory_ids), [200] * 5)
    meta = demos.metadata
    assert meta["learner"] == "trpo" and "TRPO policies" in meta["source"]
    # 4 tiny iterations do not beat the random policy; the run says so instead of hiding it.
    assert meta["optimal_beats_random"] == (meta["optimal_return"] > meta["random_return"])
    backwards = any("normalised returns run backwards" in str(w.message) for w in caught)
    assert backwards == (not meta["optimal_beats_random"])  # and loading says so again
    # Each trajectory's label is its own normalised return, clipped.
    expected = np.clip(
        normalized_return(
            meta["trajectory_returns"], meta["random_return"], meta["optimal_return"]
        ),
        0,
        1,
    )
    np.testing.assert_allclose(demos.confidence[::200], expected, rtol=1e-5)
    optimal, intermediate = meta["optimal_checkpoint"], meta["intermediate_checkpoint"]
    assert intermediate != optimal
    if optimal["iteration"] > 2:  # an earlier checkpoint exists: it must be the one taken
        assert intermediate["iteration"] < optimal["iteration"]
    # Every evaluated checkpoint is kept and loads without the training code.
    for iteration in (2, 4):
        policy = pngail_jax.load_policy(
            tmp_path / "checkpoints" / f"iter_{iteration:04d}", verbose=False
        )
        assert policy(demos.observations[:3]).shape == (3, 1)


def test_make_demos_tiny_mujoco_task(tmp_path):
    """A MuJoCo task (early terminations, so trajectories of any length) at a tiny budget."""
    flags = "--iterations 2 --eval-every 1 --seeds 1 --num-envs 2 --unroll-length 16 "
    flags += "--num-eval-episodes 1 --measure-episodes 1 --num-trajectories 3 --ratio 1:2"
    flags += " --learner ppo"  # the metadata names the learner that trained the policies
    path = make_demos.main(["--env", "Hopper-v4", "--out", str(tmp_path), *flags.split()])
    assert outputs.unaccounted(tmp_path, "make_demos") == []  # --overwrite knows all it wrote
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # 2 iterations may not beat the random policy
        demos = load_demonstrations(path)
    demos.check_env(envs.make("Hopper-v4"))
    meta = demos.metadata
    assert meta["env"] == "Hopper-v4" and meta["num_optimal_trajectories"] == 1
    assert meta["learner"] == "ppo" and "PPO policies" in meta["source"]
    lengths = np.bincount(demos.trajectory_ids)
    assert len(lengths) == 3 and lengths.sum() == demos.num_rows and lengths.max() <= 1000
    # Each trajectory's rows carry its own normalised return, clipped to [0, 1].
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    np.testing.assert_array_equal(demos.trajectory_ids[starts], [0, 1, 2])
    expected = normalized_return(
        np.array(meta["trajectory_returns"]), meta["random_return"], meta["optimal_return"]
    )
    np.testing.assert_allclose(demos.confidence[starts], np.clip(expected, 0, 1), rtol=1e-5)
    for trajectory in range(3):
        assert np.ptp(demos.confidence[demos.trajectory_ids == trajectory]) == 0


def test_bad_output_directories_fail_before_any_training(tmp_path, capsys):
    file = tmp_path / "file"
    file.write_text("")
    for out, message in (
        (file, f"--out {file} is a file, not a directory"),
        (file / "sub", f"--out {file / 'sub'}: {file} is a file, not a directory"),
    ):
        with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
            make_demos.parse_args(["--out", str(out)])
        assert f"python -m experiments.make_demos: error: {message} (usage:" in (
            capsys.readouterr().err
        )
    (tmp_path / "demos.npz").write_bytes(b"finished")
    with pytest.raises(SystemExit, match="^2$"):
        make_demos.parse_args(["--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert (
        f"--out {tmp_path} already holds a run of experiments.make_demos: --resume {tmp_path} "
        "to continue it, pass --overwrite"
    ) in err
    with pytest.raises(SystemExit, match="^2$"):  # the test's own file: not the program's
        make_demos.parse_args(["--out", str(tmp_path), "--overwrite"])
    assert (
        f"--out {tmp_path} holds a run of experiments.make_demos and files it did not make (file)"
    ) in capsys.readouterr().err
    file.unlink()
    assert make_demos.parse_args(["--out", str(tmp_path), "--overwrite"]).overwrite
    assert make_demos.parse_args(["--out", str(tmp_path / "new" / "dir")]).out.name == "dir"


RATIO_PARTS = "--ratio parts must be finite, non-negative and not both 0"


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--seeds", "0"], "--seeds must be a positive integer, got 0"),
        (["--num-trajectories", "-1"], "--num-trajectories must be a positive integer, got -1"),
        (["--measure-episodes", "0"], "--measure-episodes must be a positive integer, got 0"),
        (["--ratio", "inf:1"], f"{RATIO_PARTS}, got 'inf:1'"),
        (["--ratio", "nan:1"], f"{RATIO_PARTS}, got 'nan:1'"),
        (["--ratio", "1e308:1e308"], f"{RATIO_PARTS}, got '1e308:1e308'"),  # the sum overflows
        (
            ["--intermediate-target", "nan"],
            "--intermediate-target must be a finite number, got nan",
        ),
        (["--env", "CartPole"], "--env: unknown environment 'CartPole'; available: Pendulum-v1"),
    ],
)
def test_bad_flags_are_named(flags, message, tmp_path, capsys):
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        make_demos.parse_args(["--out", str(tmp_path), *flags])
    assert f"python -m experiments.make_demos: error: {message}" in capsys.readouterr().err


def test_rollout_episodes_stop_counting_after_termination():
    env = envs.make("Pendulum-v1", max_episode_steps=7)
    episodes = jax.jit(lambda keys: rollout_episodes(env, lambda obs, key: jnp.zeros(1), keys))(
        jax.random.split(jax.random.key(0), 3)
    )
    assert episodes.observations.shape == (3, 7, 3) and episodes.valid.all()
    np.testing.assert_allclose(episodes.returns, episodes.rewards.sum(axis=1), rtol=1e-6)
