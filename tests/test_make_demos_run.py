"""A demonstration making's run record and its resume (``jobs.make_demos_run``, and
``experiments.make_demos --resume DIR``): a making cut short resumes to the demonstrations of an
uninterrupted one, and every resume that cannot be trusted is refused in one line."""

import dataclasses
import json
import shutil

import jax
import numpy as np
import pytest

from pngail_jax.analysis.runs import sealed_part
from pngail_jax.demos import load_demonstrations
from pngail_jax.jobs import chunks
from pngail_jax.jobs import make_demos as make_demos_job
from pngail_jax.jobs.make_demos import make_demonstrations
from pngail_jax.jobs.make_demos_run import making_document
from pngail_jax.programs import make_demos
from pngail_jax.storage import outputs
from pngail_jax.storage.integrity import CONFIG_SEAL, OUTPUT_LIST, write_sealed

# Three blocks of two iterations: a cut after the second block's checkpoint restores block 2
# and reads block 1's policies back from checkpoints/iter_0002/.
FLAGS = ["--env", "Pendulum-v1", "--iterations", "6", "--eval-every", "2", "--seeds", "2",
         "--num-envs", "4", "--unroll-length", "50", "--num-trajectories", "5",
         "--measure-episodes", "4"]  # fmt: skip
# What a finished making leaves (training/, the learner's whole state, goes at the end).
FINISHED = [".config.sealed.json", ".pngail-outputs.json", ".pngail-run.json", "checkpoints",
            "config.json", "demos.npz", "normalizer.json"]  # fmt: skip


def _recording_candidates(patch) -> list:
    """Records (through ``patch``) the candidates phase 2 picks among: every evaluated
    policy, as (iteration, seed, eval_return, its arrays)."""
    pick, candidates = make_demos_job.pick_policies, []

    def recording(config, env, snapshots, episodes):
        candidates.extend(
            (s.iteration, s.seed, s.eval_return, jax.tree.leaves((s.policy_params, s.normalizer)))
            for s in snapshots
        )
        return pick(config, env, snapshots, episodes)

    patch.setattr(make_demos_job, "pick_policies", recording)
    return candidates


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    """An uninterrupted making, and its candidates (``_recording_candidates``)."""
    out = tmp_path_factory.mktemp("whole") / "run"
    with pytest.MonkeyPatch.context() as patch:
        candidates = _recording_candidates(patch)
        make_demos.main([*FLAGS, "--out", str(out)])
    return out, candidates


def _cut_after_second_block(out, monkeypatch):
    """The making of ``FLAGS`` into ``out``, stopped (as by Ctrl-C) just after its second
    block's training checkpoint: before that block's policies are kept."""
    save, saved = chunks.save_checkpoint, []

    def save_then_stop(*args, **kwargs):
        save(*args, **kwargs)
        saved.append(args[0])
        if len(saved) == 2:
            raise KeyboardInterrupt

    monkeypatch.setattr(chunks, "save_checkpoint", save_then_stop)
    with pytest.raises(SystemExit, match=f"interrupted: finished blocks are kept; --resume {out}"):
        make_demos.main([*FLAGS, "--out", str(out)])
    monkeypatch.setattr(chunks, "save_checkpoint", save)
    assert not (out / "demos.npz").exists()
    assert sorted(p.name for p in (out / "training").iterdir()) == ["chunk_0001", "chunk_0002"]
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["iter_0002"]


def _assert_same_demonstrations(path, expected_path) -> None:
    made, expected = load_demonstrations(path), load_demonstrations(expected_path)
    for name in ("observations", "actions", "confidence", "trajectory_ids"):
        np.testing.assert_array_equal(getattr(made, name), getattr(expected, name), err_msg=name)
    assert made.metadata == expected.metadata


@pytest.mark.filterwarnings("ignore:.*normalised returns run backwards")  # 6 tiny iterations
def test_a_cut_making_resumes_to_the_same_demonstrations(whole, tmp_path, monkeypatch, capsys):
    whole, whole_candidates = whole
    out = tmp_path / "cut"
    _cut_after_second_block(out, monkeypatch)
    # A second run into it names --resume; --resume takes no flag but the cache's.
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        make_demos.main([*FLAGS, "--out", str(out)])
    assert f"--resume {out} to continue it, pass --overwrite" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="^2$"):
        make_demos.main(["--resume", str(out), "--seeds", "3"])
    assert "--resume DIR takes no other flags: the run's config.json has them" in (
        capsys.readouterr().err
    )
    # A kept policy damaged: the candidates would not be the uninterrupted run's.
    damaged = tmp_path / "damaged"
    shutil.copytree(out, damaged)
    (damaged / "checkpoints" / "iter_0002" / "policy.json").write_text("{}")
    with pytest.raises(SystemExit, match="the policies of iteration 2 cannot be read"):
        make_demos.main(["--resume", str(damaged)])
    began = (out / "config.json").read_text()
    candidates = _recording_candidates(monkeypatch)
    make_demos.main(["--resume", str(out)])
    assert "resumed from" in capsys.readouterr().out
    # The same candidates: iteration 2's read back, 4's from the state restored, 6's trained.
    assert [c[:3] for c in candidates] == [c[:3] for c in whole_candidates]
    assert [c[:2] for c in candidates] == [(i, s) for i in (2, 4, 6) for s in (0, 1)]
    for resumed, uninterrupted in zip(candidates, whole_candidates, strict=True):
        for made, expected in zip(resumed[3], uninterrupted[3], strict=True):
            np.testing.assert_array_equal(made, expected)
    _assert_same_demonstrations(out / "demos.npz", whole / "demos.npz")
    assert (out / "normalizer.json").read_bytes() == (whole / "normalizer.json").read_bytes()
    for iteration in ("iter_0002", "iter_0004", "iter_0006"):  # every policy kept, the same
        for run in (out, whole):
            assert (run / "checkpoints" / iteration / "digests.json").exists()
        policy = [run / "checkpoints" / iteration / "policy.json" for run in (out, whole)]
        assert policy[0].read_bytes() == policy[1].read_bytes()
    assert (out / "config.json").read_text() == began  # a resume never rewrites it
    assert sorted(p.name for p in out.iterdir()) == FINISHED
    listed = json.loads((out / OUTPUT_LIST).read_text())["files"]
    assert not any(name.startswith("training/") for name in listed)  # --overwrite knows all
    assert outputs.unaccounted(out, "make_demos") == []
    with pytest.raises(SystemExit, match="^2$"):
        make_demos.main(["--resume", str(out)])
    assert f"--resume {out}: the run is complete (its demos.npz is written)" in (
        capsys.readouterr().err
    )


def test_a_finished_making_leaves_its_sealed_config_and_no_training_state(whole):
    whole, _ = whole
    assert sorted(p.name for p in whole.iterdir()) == FINISHED
    document = json.loads((whole / "config.json").read_text())
    assert (document["program"], document["family"]) == ("make_demos", "reinforcement")
    config = document["config"]
    assert config["iterations"] == 6 and config["seeds"] == 2 and config["ratio"] == "1:4"
    assert config["argv"] == [*FLAGS, "--out", str(whole)]  # what --resume reads back
    assert document["resolved"]["rollout"]["eval_every"] == 2
    assert document["provenance"]["command_line"][:3] == ["python", "-m", "experiments.make_demos"]


def _begun(out, argv=None):
    """A making's sealed config.json in ``out`` (as one writes it before training), of
    ``FLAGS`` (``argv``: its flags; None: begun from Python); returns its config."""
    config = make_demos.parse_args([*FLAGS, "--out", str(out)]).config
    out.mkdir()
    document = making_document(config, argv)
    write_sealed(out / "config.json", document, out / CONFIG_SEAL, sealed_part(document))
    return config


def test_resume_refuses_in_one_line(tmp_path, capsys):
    """Each directory --resume cannot continue, refused before any training."""
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(SystemExit, match="^2$"):
        make_demos.main(["--resume", str(empty)])
    assert f"--resume {empty} holds no run of experiments.make_demos" in capsys.readouterr().err

    from_python = tmp_path / "from-python"
    _begun(from_python)
    assert outputs.output_owner(from_python) == "make_demos"  # known by its config.json
    with pytest.raises(SystemExit, match="^2$"):
        make_demos.main(["--resume", str(from_python)])
    assert (
        "no flags to resume with (a run begun from Python: resume it with "
        "pngail_jax.jobs.make_demos.make_demonstrations(..., resume=True))"
    ) in capsys.readouterr().err

    edited = tmp_path / "edited"
    argv = [*FLAGS, "--out", str(edited)]
    config = _begun(edited, argv)
    began = (edited / "config.json").read_text()
    document = json.loads(began)
    document["config"]["seed"], document["config"]["argv"] = 5, [*argv, "--seed", "5"]
    (edited / "config.json").write_text(json.dumps(document))
    with pytest.raises(SystemExit, match="config.json was changed since the run began") as stop:
        make_demos.main(["--resume", str(edited)])
    assert "config.seed: was 0, now 5" in str(stop.value)
    (edited / "config.json").write_text(began)
    sealed = (edited / CONFIG_SEAL).read_bytes()
    (edited / CONFIG_SEAL).unlink()
    with pytest.raises(SystemExit, match="its seal .config.sealed.json is missing"):
        make_demos.main(["--resume", str(edited)])
    (edited / CONFIG_SEAL).write_bytes(sealed)

    from pngail_jax.jobs.errors import RunError

    other = make_demos.parse_args([*FLAGS, "--seed", "1", "--out", str(tmp_path / "o")]).config
    with pytest.raises(RunError) as refused:
        make_demonstrations(other, edited, resume=True, command=argv)
    assert str(refused.value) == (
        f"cannot resume {edited}: these flags give another run (config.seed: was 0, now 1)"
    )
    (edited / "demos.npz").write_bytes(b"finished")
    with pytest.raises(RunError, match=r"the run is complete \(its demos.npz is written\)"):
        make_demonstrations(config, edited, resume=True, command=argv)
    assert not any(p.name == "training" for p in edited.iterdir())  # nothing was trained


@pytest.mark.filterwarnings("ignore:.*normalised returns run backwards")  # 6 tiny iterations
def test_a_folder_a_job_keeps_continues_its_own_cut_making_and_replaces_another(
    whole, tmp_path, monkeypatch, capsys
):
    """``continue_cut`` (the demonstrations' cache, a plan's folder): a making of the same
    config cut short there continues to the uninterrupted one's demonstrations; a cut making
    of another config is replaced."""
    whole, _ = whole
    config = make_demos.parse_args([*FLAGS, "--out", str(tmp_path / "unused")]).config
    save, saved = chunks.save_checkpoint, []

    def save_then_stop(*args, **kwargs):
        save(*args, **kwargs)
        saved.append(args[0])
        if len(saved) % 2 == 0:  # the second block of each making
            raise KeyboardInterrupt

    cut, other = tmp_path / "cut", tmp_path / "other"
    monkeypatch.setattr(chunks, "save_checkpoint", save_then_stop)
    for out, made in ((cut, config), (other, dataclasses.replace(config, seed=1))):
        with pytest.raises(KeyboardInterrupt):
            make_demonstrations(made, out)  # from Python, as the cache and a plan begin them
        assert not (out / "demos.npz").exists() and (out / "training").is_dir()
    monkeypatch.setattr(chunks, "save_checkpoint", save)
    capsys.readouterr()

    make_demonstrations(config, cut, overwrite=True, continue_cut=True)
    printed = capsys.readouterr().out
    assert f"continuing the making cut short in {cut}" in printed and "resumed from" in printed
    _assert_same_demonstrations(cut / "demos.npz", whole / "demos.npz")
    assert sorted(p.name for p in cut.iterdir()) == FINISHED

    make_demonstrations(config, other, overwrite=True, continue_cut=True)
    printed = capsys.readouterr().out
    assert "continuing" not in printed and "resumed from" not in printed
    _assert_same_demonstrations(other / "demos.npz", whole / "demos.npz")  # made afresh
    assert json.loads((other / "config.json").read_text())["config"]["seed"] == 0
