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
    document = json.loads((run_dir / "config.json").read_text())
    # Every run's layout (analysis.runs.run_document): what was asked, what it resolved to.
    assert (document["program"], document["family"]) == ("train_rl", "reinforcement")
    assert document.keys() == {"program", "family", "config", "resolved", "provenance"}
    config, resolved = document["config"], document["resolved"]
    assert config["iterations"] == 4 and config["seeds"] == 2 and config["seed"] == 0
    assert config["learner"]["name"] == "trpo" and config["learner"]["trpo"]["fisher"] == (
        "gauss_newton"
    )
    assert config["argv"][config["argv"].index("--iterations") + 1] == "4"
    assert resolved["rollout"]["num_iterations"] == 4 and resolved["rollout"]["num_envs"] == 4
    assert resolved["hyperparams"]["bootstrap_truncation"] is True
    assert document["provenance"]["command_line"][:3] == ["python", "-m", "experiments.train_rl"]


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
    assert (
        f"--out {run_dir} already holds a run of experiments.train_rl: --resume {run_dir} to "
        "continue it, pass --overwrite"
    ) in (capsys.readouterr().err)
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

    argv = [*json.loads((run_dir / "config.json").read_text())["config"]["argv"]]
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
    config = edited["config"]
    config["seed"], config["argv"] = 5, [*config["argv"], "--seed", "5"]
    config_path.write_text(json.dumps(edited))
    with pytest.raises(SystemExit, match="config.json was changed since the run began") as stop:
        train_rl.main(["--resume", str(out)])
    assert "config.seed: was 0, now 5" in str(stop.value)
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
    assert config_path.read_text() == began  # a resume never rewrites config.json
    with pytest.raises(SystemExit, match="^2$"):
        train_rl.main(["--resume", str(out)])
    assert f"--resume {out}: the run is complete (its policy.json is written)" in (
        capsys.readouterr().err
    )


def _config_of(argv):
    """The TrainRLConfig that experiments.train_rl's flags ``argv`` give."""
    from pngail_jax.jobs.train_rl import TrainRLConfig
    from pngail_jax.programs.cli import config_from

    parser = train_rl.build_parser()
    args = parser.parse_args(argv)
    train_rl._check(parser, args)
    return config_from(TrainRLConfig, args)


def _flat_document(config, argv) -> dict:
    """config.json as train_rl wrote it before every run's layout (analysis.runs.run_document):
    flat, as TrainRLConfig.document wrote it at commit 3152989."""
    import dataclasses

    return json.loads(
        json.dumps(
            {
                "env": config.env,
                "env_options": config.settings.env_options,
                "settings": dataclasses.asdict(config.settings),
                "seeds": config.seeds,
                "seed": config.seed,
                "learner": config.learner.name,
                "rollout": dataclasses.asdict(config.rollout_config),
                config.learner.name: dataclasses.asdict(config.learner.settings),
                "hyperparams": jax.tree.map(lambda x: x.item(), config.hyperparams).__dict__,
                "argv": list(argv),
            }
        )
    )


def test_a_changed_config_is_refused_on_resume_in_one_line(run_dir, tmp_path, monkeypatch):
    """train_rl(config, resume=True) with another config than the run began with: one line
    naming the field, in the layout the run began in."""
    import dataclasses

    from pngail_jax.jobs.errors import RunError
    from pngail_jax.jobs.train_rl import train_rl as train_rl_job

    out = tmp_path / "stopped"
    _stopped_after_first_block(run_dir, out, monkeypatch)
    argv = json.loads((out / "config.json").read_text())["config"]["argv"]
    other = dataclasses.replace(_config_of(argv), seed=1)
    with pytest.raises(RunError) as refused:
        train_rl_job(other, out, resume=True, command=argv)
    assert str(refused.value) == (
        f"cannot resume {out}: these flags give another run (config.seed: was 0, now 1)"
    )


@pytest.mark.parametrize("layout", ["flat", "rollout in trpo"])
def test_a_run_begun_in_an_older_layout_resumes(run_dir, tmp_path, monkeypatch, layout):
    """A run whose sealed config.json has one of train_rl's layouts before every run's (the
    flat one the code wrote until commit 3152989, and the one before the rollout's settings
    had their own section, when "trpo" held them beside TRPO's) resumes to the uninterrupted
    run's numbers, its config.json never rewritten; a changed config is refused in one line
    naming the field in that layout's keys."""
    import dataclasses

    from pngail_jax.jobs.errors import RunError
    from pngail_jax.jobs.train_rl import flat_document
    from pngail_jax.jobs.train_rl import train_rl as train_rl_job
    from pngail_jax.storage.integrity import CONFIG_SEAL, write_sealed

    out = tmp_path / "old-layout"
    _stopped_after_first_block(run_dir, out, monkeypatch)
    today = json.loads((out / "config.json").read_text())
    argv = today["config"]["argv"]
    config = _config_of(argv)
    old = _flat_document(config, argv)
    assert flat_document(today) == old and flat_document(old) == old
    if layout == "rollout in trpo":
        old = {key: value for key, value in old.items() if key != "rollout"}
        old["trpo"] = {**today["resolved"]["rollout"], **today["config"]["learner"]["trpo"]}
    write_sealed(out / "config.json", old, out / CONFIG_SEAL)
    written = (out / "config.json").read_bytes()
    with pytest.raises(RunError) as refused:
        train_rl_job(dataclasses.replace(config, seed=1), out, resume=True, command=argv)
    assert str(refused.value) == (
        f"cannot resume {out}: these flags give another run (seed: was 0, now 1)"
    )
    train_rl.main(["--resume", str(out)])
    assert (out / "metrics.csv").read_bytes() == (run_dir / "metrics.csv").read_bytes()
    assert (out / "config.json").read_bytes() == written


def test_a_run_begun_from_python_is_not_resumed_by_the_program(tmp_path, capsys):
    """A run begun with jobs.train_rl (no flags: "argv" null) cannot be resumed by
    --resume DIR, which would read this process's own flags instead: one line says how."""
    from pngail_jax.jobs.train_rl import TrainRLConfig
    from pngail_jax.storage.integrity import CONFIG_SEAL, write_sealed

    out = tmp_path / "from-python"
    out.mkdir()
    document = TrainRLConfig(iterations=10, seeds=2).document()
    assert document["config"]["argv"] is None
    write_sealed(out / "config.json", document, out / CONFIG_SEAL)
    assert outputs.output_owner(out) == "train_rl"  # known by its program, without a marker
    with pytest.raises(SystemExit, match="^2$"):
        train_rl.main(["--resume", str(out)])
    assert "no flags to resume with (a run begun from Python" in capsys.readouterr().err


def test_older_layouts_are_upgraded_to_the_flat_one():
    """upgrade_document: the layout with the rollout's settings in "trpo" (a PPO run's "trpo"
    held TRPO's unused settings, which go) and the one before the value fit's epochs in the
    flat layout's last form; that form and today's layout unchanged."""
    from pngail_jax.jobs.train_rl import TrainRLConfig, upgrade_document

    today = TrainRLConfig(iterations=10, seeds=2).document(["--seeds", "2"])
    assert upgrade_document(today) is today
    flat = _flat_document(TrainRLConfig(iterations=10, seeds=2), ["--seeds", "2"])
    assert upgrade_document(flat) is flat
    old = {key: value for key, value in flat.items() if key != "rollout"}
    old["trpo"] = {**flat["rollout"], **flat["trpo"]}
    assert upgrade_document(old) == flat
    ppo = upgrade_document({**old, "learner": "ppo", "ppo": {"num_epochs": 10}})
    assert "trpo" not in ppo and ppo["rollout"] == flat["rollout"] and ppo["ppo"]
    trpo = {key: value for key, value in flat["trpo"].items() if key != "num_value_epochs"}
    before_epochs = {**flat, "trpo": trpo}  # the layout before the value fit's epochs
    assert upgrade_document(before_epochs) == flat
    old["trpo"].pop("num_value_epochs")
    assert upgrade_document(old) == flat


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
    assert config.document()["config"]["learner"]["trpo"]["num_value_epochs"] == 3
