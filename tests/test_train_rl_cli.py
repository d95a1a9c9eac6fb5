"""experiments.train_rl end to end (tiny budget) and pngail_jax.load_policy."""

import json

import jax
import numpy as np
import pytest
from conftest import sigterm_to_self

import pngail_jax
from pngail_jax.networks import GaussianPolicy
from pngail_jax.programs import train_rl
from pngail_jax.storage import outputs


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("trpo")
    train_rl.main(
        [
            "--env",
            "Pendulum-v1",
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
            "--out",
            str(out),
        ]
    )
    return out


def test_outputs_are_written(run_dir):
    for name in ("config.json", "metrics.csv", "learning_curve.png", "policy.json"):
        assert (run_dir / name).stat().st_size > 0, name
    assert outputs.unaccounted(run_dir, "train_rl") == []  # --overwrite knows all it wrote
    lines = (run_dir / "metrics.csv").read_text().splitlines()
    assert lines[0].startswith("seed,iteration,env_steps,eval/return")
    assert len(lines) == 1 + 2 * 4
    config = json.loads((run_dir / "config.json").read_text())
    assert config["rollout"]["num_iterations"] == 4 and config["seeds"] == 2
    assert config["trpo"]["fisher"] == "gauss_newton" and "num_envs" not in config["trpo"]


def test_load_policy_picks_best_seed_and_acts(run_dir, capsys):
    metadata = json.loads((run_dir / "policy.json").read_text())
    policy = pngail_jax.load_policy(run_dir)
    assert policy.seed == int(np.argmax(metadata["final_eval_returns"]))
    assert f"seed {policy.seed} of 2" in capsys.readouterr().out
    obs = np.array([1.0, 0.0, 0.5], np.float32)
    action = policy(obs)
    assert action.shape == (1,) and np.all(np.abs(action) <= 2.0)
    assert policy(np.stack([obs, obs])).shape == (2, 1)
    # The same numbers as the network itself, clipped to the torque bound.
    other = pngail_jax.load_policy(run_dir, seed=1 - policy.seed)
    assert not np.allclose(other(obs), action)


def test_load_policy_matches_saved_parameters(tmp_path):
    from pngail_jax.rl.on_policy import ObservationNormalizer
    from pngail_jax.storage.checkpoint import save_policies

    policy = GaussianPolicy(action_size=2, hidden_sizes=(8,))
    params = jax.vmap(lambda k: policy.init(k, np.zeros(3, np.float32)))(
        jax.random.split(jax.random.key(0), 2)
    )
    normalizer = ObservationNormalizer.create(3).update(np.arange(12.0).reshape(4, 3))
    stacked = jax.tree.map(lambda x: np.stack([x, x]), normalizer)
    save_policies(
        tmp_path,
        env_name="Test",
        observation_size=3,
        action_low=np.array([-5.0, -5.0]),
        action_high=np.array([5.0, 5.0]),
        hidden_sizes=(8,),
        policy_params=params,
        normalizer=stacked,
        normalize_observations=True,
        final_eval_returns=np.array([1.0, 2.0]),
    )
    loaded = pngail_jax.load_policy(tmp_path, seed=0, verbose=False)
    obs = np.array([[3.0, -1.0, 2.0]], np.float32)
    expected, _ = policy.apply(jax.tree.map(lambda x: x[0], params), normalizer(obs))
    # jitted vs eager: two programs, float32 sums may round differently in the last bits
    np.testing.assert_allclose(loaded(obs), np.clip(expected, -5, 5), rtol=1e-5, atol=1e-5)


def test_load_policy_errors(run_dir, tmp_path):
    with pytest.raises(FileNotFoundError, match="no policy.json"):
        pngail_jax.load_policy(tmp_path)
    with pytest.raises(ValueError, match=r"seed must be in \[0, 2\)"):
        pngail_jax.load_policy(run_dir, seed=5)
    with pytest.raises(ValueError, match=r"observation must have shape \(\.\.\., 3\)"):
        pngail_jax.load_policy(run_dir, verbose=False)(np.zeros(4))


def test_cli_rejects_bad_arguments(capsys):
    for argv, message in [
        (["--env", "CartPole-v1"], "--env: unknown environment 'CartPole-v1'; available: "),
        (
            ["--iterations", "15", "--eval-every", "10"],
            "--iterations (15) must be a multiple of the evaluation interval (10, --eval-every)",
        ),
    ]:
        with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
            train_rl.parse_args(argv)
        assert f"python -m experiments.train_rl: error: {message}" in capsys.readouterr().err


def test_finished_work_is_not_overwritten_without_the_flag(run_dir, tmp_path, capsys):
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        train_rl.parse_args(["--out", str(run_dir)])
    assert f"--out {run_dir} already holds a run of experiments.train_rl: pass --overwrite" in (
        capsys.readouterr().err
    )
    assert train_rl.parse_args(["--out", str(run_dir), "--overwrite"]).overwrite
    a_file = tmp_path / "notes.txt"
    a_file.write_text("mine")
    with pytest.raises(SystemExit, match="^2$"):
        train_rl.parse_args(["--out", str(a_file)])
    assert f"--out {a_file} is a file, not a directory" in capsys.readouterr().err
    assert a_file.read_text() == "mine"


def test_load_policy_checks_cannot_be_switched_off_and_bad_inputs_are_named(run_dir, tmp_path):
    import shutil

    from pngail_jax.storage.integrity import IntegrityError

    copy = tmp_path / "policy"
    shutil.copytree(run_dir, copy)
    metadata = json.loads((copy / "policy.json").read_text())
    policy = pngail_jax.load_policy(copy, verbose=False)
    with pytest.raises(ValueError, match="observation contains NaN or infinite values"):
        policy(np.array([np.nan, 0.0, 0.0]))
    for seed in (0.5, "0", True):
        with pytest.raises(ValueError, match="seed must be an integer in"):
            pngail_jax.load_policy(copy, seed=seed, verbose=False)
    assert pngail_jax.load_policy(copy, seed=np.int64(0), verbose=False).seed == 0
    (copy / "policy.json").write_text(json.dumps({**metadata, "format_version": 1}))
    with pytest.raises(IntegrityError, match="policy.json: damaged"):  # digests still checked
        pngail_jax.load_policy(copy, verbose=False)
    lacking = {k: v for k, v in metadata.items() if k != "hidden_sizes"}
    (copy / "digests.json").unlink()
    (copy / "policy.json").write_text(json.dumps({**lacking, "format_version": 1}))
    with pytest.raises(IntegrityError, match=r"lacks \['hidden_sizes'\]"):
        pngail_jax.load_policy(copy, verbose=False)


def _stopped_after_first_block(run_dir, out, monkeypatch):
    """The fixture's run again into ``out``, stopped after its first block's checkpoint."""
    from pngail_jax.jobs import chunks

    argv = [*json.loads((run_dir / "config.json").read_text())["argv"]]
    argv[argv.index("--out") + 1] = str(out)
    save = chunks.save_checkpoint

    def save_then_stop(*args, **kwargs):
        save(*args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(chunks, "save_checkpoint", save_then_stop)
    with pytest.raises(SystemExit, match=f"--resume {out} continues"):
        train_rl.main(argv)
    assert not (out / "policy.json").exists() and (out / "checkpoints" / "chunk_0001").is_dir()
    monkeypatch.setattr(chunks, "save_checkpoint", save)


def test_an_interrupted_run_resumes_to_the_same_numbers(run_dir, tmp_path, monkeypatch, capsys):
    """The fixture's run, stopped after its first block's checkpoint, then --resume DIR:
    metrics.csv byte-identical to the uninterrupted run's."""
    out = tmp_path / "stopped"
    _stopped_after_first_block(run_dir, out, monkeypatch)
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        train_rl.main(["--resume", str(out), "--seeds", "3"])  # its own flags only
    assert "--resume DIR takes no other flags: the run's config.json has them" in (
        capsys.readouterr().err
    )
    # config.json edited so that its flags and fields agree: refused by the seal, which keeps
    # what the run began with; a copy without its dot-files has no seal: refused too.
    config_path = out / "config.json"
    began = config_path.read_text()
    edited = json.loads(began)
    edited["seed"], edited["argv"] = 5, [*edited["argv"], "--seed", "5"]
    config_path.write_text(json.dumps(edited))
    with pytest.raises(SystemExit, match="config.json was changed since the run began") as stop:
        train_rl.main(["--resume", str(out)])
    assert "seed: was 0, now 5" in str(stop.value)
    config_path.write_text(began)
    sealed = (out / ".config.sealed.json").read_bytes()
    (out / ".config.sealed.json").unlink()
    with pytest.raises(SystemExit, match="its seal .config.sealed.json is missing"):
        train_rl.main(["--resume", str(out)])
    (out / ".config.sealed.json").write_bytes(sealed)
    train_rl.main(["--resume", str(out)])
    assert "resumed from" in capsys.readouterr().out
    assert (out / "metrics.csv").read_bytes() == (run_dir / "metrics.csv").read_bytes()
    assert not (out / "checkpoints").exists()
    with pytest.raises(SystemExit, match="^2$"):
        train_rl.main(["--resume", str(out)])
    assert f"--resume {out}: the run is complete (its policy.json is written)" in (
        capsys.readouterr().err
    )


def test_a_run_begun_before_the_rollout_section_resumes(run_dir, tmp_path, monkeypatch):
    """A run whose sealed config.json has the layout from before the rollout's settings had
    their own section ("trpo" held them beside TRPO's) resumes to the uninterrupted run's
    numbers; in that layout a PPO run's "trpo" held TRPO's unused settings, which go."""
    from pngail_jax.jobs.train_rl import upgrade_document
    from pngail_jax.storage.integrity import CONFIG_SEAL, write_sealed

    out = tmp_path / "old-layout"
    _stopped_after_first_block(run_dir, out, monkeypatch)
    today = json.loads((out / "config.json").read_text())
    old = {key: value for key, value in today.items() if key != "rollout"}
    old["trpo"] = {**today["rollout"], **today["trpo"]}
    write_sealed(out / "config.json", old, out / CONFIG_SEAL)
    assert upgrade_document(old) == today and upgrade_document(today) is today
    train_rl.main(["--resume", str(out)])
    assert (out / "metrics.csv").read_bytes() == (run_dir / "metrics.csv").read_bytes()
    ppo = upgrade_document({**old, "learner": "ppo", "ppo": {"num_epochs": 10}})
    assert "trpo" not in ppo and ppo["rollout"] == today["rollout"] and ppo["ppo"]
    trpo = {key: value for key, value in today["trpo"].items() if key != "num_value_epochs"}
    before_epochs = {**today, "trpo": trpo}  # the layout before the value fit's epochs
    assert upgrade_document(before_epochs) == today
    old["trpo"].pop("num_value_epochs")
    assert upgrade_document(old) == today


def test_resume_checks_again_under_the_lock(run_dir, tmp_path, monkeypatch, capsys):
    """A run another process finishes between the checks of --resume and taking the lock is
    refused, not trained again over its policy."""
    import contextlib
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(run_dir, copy)
    policy = (copy / "policy.json").read_bytes()
    (copy / "policy.json").unlink()
    from pngail_jax.storage import outputs

    lock = outputs.run_lock

    @contextlib.contextmanager
    def lock_after_another_finished(directory, program, wait=False):
        (copy / "policy.json").write_bytes(policy)
        with lock(directory, program, wait):
            yield

    monkeypatch.setattr(outputs, "run_lock", lock_after_another_finished)
    with pytest.raises(SystemExit, match="the run is complete"):
        train_rl.main(["--resume", str(copy)])
    assert (copy / "policy.json").read_bytes() == policy


def test_a_sigterm_releases_the_lock_and_says_how_to_resume(tmp_path, monkeypatch):
    from pngail_jax.storage.outputs import LOCK

    def terminated(*args):
        assert (tmp_path / "run" / LOCK).exists()
        sigterm_to_self()

    from pngail_jax.jobs import train_rl as train_rl_job

    monkeypatch.setattr(train_rl_job, "_train", terminated)
    argv = ["--env", "Pendulum-v1", "--iterations", "10", "--out", str(tmp_path / "run")]
    with pytest.raises(SystemExit, match="interrupted: finished blocks are kept; --resume"):
        train_rl.main(argv)
    assert not (tmp_path / "run" / LOCK).exists()


def test_value_epochs_are_refused_for_ppo_in_one_line():
    from pngail_jax.config.learner import LearnerConfig, TRPOConfig
    from pngail_jax.config.validation import ConfigError
    from pngail_jax.jobs.train_rl import TrainRLConfig

    more_epochs = TRPOConfig(num_value_epochs=3)
    with pytest.raises(ConfigError, match="num_value_epochs is TRPO's value fit"):
        TrainRLConfig(learner=LearnerConfig(name="ppo", trpo=more_epochs))
    config = TrainRLConfig(learner=LearnerConfig(trpo=more_epochs))
    assert config.learner.settings.num_value_epochs == 3
    assert config.document()["trpo"]["num_value_epochs"] == 3
