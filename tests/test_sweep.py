"""End to end: a tiny sweep writes every output; a killed run resumes to the same numbers."""

import csv
import dataclasses
import hashlib
import itertools
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import metrics_numbers, sigterm_to_self, tiny_sweep_args

from pngail_jax.analysis.runs import sealed_part
from pngail_jax.demos import save_npz
from pngail_jax.jobs import chunks, record
from pngail_jax.jobs import demonstrations as demos_job
from pngail_jax.programs import sweep
from pngail_jax.storage import outputs
from pngail_jax.storage.integrity import sealed_differences
from pngail_jax.storage.outputs import MARKER

SUMMARY_KEYS = {  # the fields of every earlier summary.json, and the new interval ones
    "final_return_mean",
    "final_return_std",
    "final_normalized_return_mean",
    "final_normalized_return_std",
    "num_seeds",
    "final_normalized_return_iqm",
    "final_normalized_return_ci95",
}


def read_csv(path):
    with open(path) as file:
        return list(csv.DictReader(file))


@pytest.fixture(scope="module")
def finished(demos_path, tmp_path_factory):
    """One uninterrupted tiny run, shared by the tests below (they damage copies of it)."""
    out = tmp_path_factory.mktemp("runs") / "run"
    sweep.main(tiny_sweep_args(demos_path, out))
    return out


def copy_run(finished, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(finished, copy)
    return copy


def test_sweep_writes_every_output(finished, demos_path, tmp_path, capsys):
    out = finished
    for name in ("config.json", "metrics.csv", "curves.png", "summary.md", "summary.json"):
        assert (out / name).stat().st_size > 0, name
    assert outputs.unaccounted(out, "sweep") == []  # --overwrite knows all it wrote
    rows = read_csv(out / "metrics.csv")
    assert len(rows) == 2 * 2 * 4  # methods x seeds x iterations
    assert list(rows[0]) == list(sweep_columns())
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary) >= {"methods", "train_env_steps_per_second", "compile_seconds"}
    assert summary["complete"] and summary["iterations_done"] == summary["iterations"] == 4
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
    # What decides whether another run gives the same bits (docs/sweep.md).
    assert config["provenance"]["cpu_model"] and "xla_flags" in config["provenance"]
    assert config["resolved"]["trainer"]["rollout"]["num_envs"] == 4
    assert config["resolved"]["inputs"]["demonstrations"]["sha256"].startswith("sha256:")
    check_exported_policies(out, final)

    # A new run from the saved config is the same run (logging changes no number).
    copy = tmp_path / "copy"
    sweep.main(["--config", str(out / "config.json"), "--out", str(copy), "--log", "tensorboard"])
    assert metrics_numbers(copy / "metrics.csv") == metrics_numbers(out / "metrics.csv")
    assert json.loads((copy / "config.json").read_text())["config"]["log"] == ["tensorboard"]
    assert any((copy / "tensorboard").iterdir())
    with pytest.raises(SystemExit, match="^2$"):  # a second run into the same directory
        sweep.parse_args(tiny_sweep_args(demos_path, out))
    assert (
        f"--out {out} already holds a run of experiments.sweep: --resume {out} to continue it"
    ) in capsys.readouterr().err
    # A folder as --demos (here the run's) is refused naming it, before any folder is made.
    new = tmp_path / "new"
    folder = re.escape(str(finished))
    with pytest.raises(SystemExit, match=f"^demonstrations: {folder}: is a directory, not a file"):
        sweep.main(tiny_sweep_args(demos_path=finished, out=new))
    assert not new.exists()


def killed_at_checkpoint(number):
    """chunks.save_checkpoint as a process killed when it reaches checkpoint ``number``."""
    save = chunks.save_checkpoint

    def killed(directory, progress, host_state, writer):
        if progress.chunks_done == number:
            raise Killed
        save(directory, progress, host_state, writer)

    return killed


class Killed(BaseException):
    """A kill -9 stand-in: nothing after it runs."""


def test_a_killed_run_says_partial_and_resumes_exactly(finished, demos_path, tmp_path, monkeypatch):
    out = tmp_path / "run"
    killed_at_the_second_checkpoint = killed_at_checkpoint(2)
    monkeypatch.setattr(chunks, "save_checkpoint", killed_at_the_second_checkpoint)
    with pytest.raises(Killed):
        sweep.main(tiny_sweep_args(demos_path, out))
    monkeypatch.undo()
    summary = json.loads((out / "summary.json").read_text())
    assert not summary["complete"] and summary["iterations_done"] == 2
    assert "Partial: 2 of 4 iterations" in (out / "summary.md").read_text()
    assert not (out / "policies").exists()
    sweep.main(["--resume", str(out)])
    assert metrics_numbers(out / "metrics.csv") == metrics_numbers(finished / "metrics.csv")
    assert json.loads((out / "summary.json").read_text())["complete"]
    with np.load(finished / "checkpoints" / "chunk_0002" / "metrics.npz") as uninterrupted:
        with np.load(out / "checkpoints" / "chunk_0002" / "metrics.npz") as resumed:
            for name in uninterrupted.files:  # the same program: bit for bit
                np.testing.assert_array_equal(resumed[name], uninterrupted[name], err_msg=name)


def flip_a_bit(path, position=None):
    data = bytearray(path.read_bytes())
    data[len(data) // 2 if position is None else position] ^= 0x10
    path.write_bytes(bytes(data))


def largest_file(directory):
    return max((p for p in directory.rglob("*") if p.is_file()), key=lambda p: p.stat().st_size)


def test_a_damaged_checkpoint_is_named_and_the_older_one_resumes(finished, tmp_path, capsys):
    out = copy_run(finished, tmp_path)
    damaged = largest_file(out / "checkpoints" / "chunk_0002" / "state")
    flip_a_bit(damaged)
    (out / "metrics.csv").unlink()
    sweep.main(["--resume", str(out)])
    printed = capsys.readouterr().out
    assert f"checkpoint chunk_0002 is damaged or incomplete: {damaged}: damaged" in printed
    assert "trying chunk_0001" in printed and "chunk_0001 (iteration 2)" in printed
    assert metrics_numbers(out / "metrics.csv") == metrics_numbers(finished / "metrics.csv")


@pytest.mark.parametrize("file", ["progress.json", "metrics.npz", "digests.json", "truncated"])
def test_checkpoint_damage_of_every_kind_falls_back(finished, tmp_path, capsys, file):
    checkpoints = copy_run(finished, tmp_path) / "checkpoints"
    newest = checkpoints / "chunk_0002"
    if file == "truncated":
        target = largest_file(newest / "state")
        target.write_bytes(target.read_bytes()[:100])
    else:
        target = newest / file
        flip_a_bit(target, position=2)
    assert chunks.intact_checkpoint(checkpoints) == checkpoints / "chunk_0001"
    assert f"chunk_0002 is damaged or incomplete: {newest}" in capsys.readouterr().out
    flip_a_bit(largest_file(checkpoints / "chunk_0001" / "state"))
    assert chunks.intact_checkpoint(checkpoints) is None
    assert "no older checkpoint to fall back on" in capsys.readouterr().out


def test_resume_refuses_changed_inputs_and_damaged_configs(finished, tmp_path, capsys):
    from pngail_jax.demos import load_npz
    from pngail_jax.storage.integrity import file_record, seal

    out = copy_run(finished, tmp_path)
    config = json.loads((out / "config.json").read_text())
    demos = tmp_path / "own_demos.npz"  # the copy gets a demonstrations file of its own
    shutil.copy(config["resolved"]["demos_path"], demos)
    config["resolved"]["demos_path"] = str(demos)
    config["resolved"]["inputs"]["demonstrations"] = file_record(demos)
    (out / "config.json").write_text(json.dumps(config))
    seal(out / record.SEAL, record.sealed_part(config))  # as if the run had begun with it
    original = load_npz(demos)
    actions = original.actions.copy()
    actions[0] += 0.5
    save_npz(demos, dataclasses.replace(original, actions=actions))
    with pytest.raises(SystemExit, match=f"demonstrations {demos} has changed"):
        sweep.main(["--resume", str(out)])
    assert "compiling" not in capsys.readouterr().out  # refused before the compile
    assert sweep.parse_args(["--resume", str(out), "--allow-changed-inputs"]).resume
    demos.unlink()
    with pytest.raises(SystemExit, match=f"demonstrations {demos} is gone"):
        sweep.main(["--resume", str(out)])
    (out / "config.json").write_text(json.dumps(config)[:-20])
    with pytest.raises(SystemExit, match="config.json: damaged run config, not valid JSON"):
        sweep.main(["--resume", str(out)])


def test_a_damaged_policy_is_refused_naming_the_file(finished, tmp_path):
    from pngail_jax import load_policy
    from pngail_jax.storage.integrity import IntegrityError

    policies = copy_run(finished, tmp_path) / "policies" / "gail"
    damaged = largest_file(policies / "policy_params")
    flip_a_bit(damaged)
    with pytest.raises(IntegrityError, match=f"{damaged}: damaged"):
        load_policy(policies)
    (policies / "policy.json").write_text("{")
    with pytest.raises(IntegrityError, match="policy.json: damaged policy description"):
        load_policy(policies)


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
    from pngail_jax.analysis.report import CSV_COLUMNS

    return CSV_COLUMNS


def test_bad_flags_are_named(demos_path, tmp_path, capsys):
    for argv, message in [
        (["--methods", "gail,pu-gail"], "--methods: unknown method(s) ['pu-gail']; available: "),
        (["--env", "CartPole"], "--env: unknown environment 'CartPole'; available: Pendulum-v1"),
        (["--label-ratio", "0.2,1.5"], "--label-ratio values must lie in (0, 1), got [0.2, 1.5]"),
        (["--resume", str(tmp_path), "--seeds", "3"], "--resume DIR takes no other flags"),
        (
            ["--iterations", "25", "--eval-every", "10"],
            "--iterations (25) must be a multiple of the evaluation interval (10,",
        ),
        (
            ["--env", "Hopper", "--iterations", "60"],  # the table: every 50
            "--iterations (60) must be a multiple of the evaluation interval (50,",
        ),
        (
            ["--env", "Hopper", "--solver", "2"],
            "--solver: solver must be 'own', 'fast' or 'I/L' (positive Newton / line-search "
            "iteration counts, e.g. 4/50), got '2'",
        ),
        (["--num-envs", "0"], "--num-envs must be a positive integer, got 0"),
        (["--random-return", "-1200"], "--random-return needs optimal_return"),
    ]:
        with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
            sweep.parse_args(argv)
        assert f"python -m experiments.sweep: error: {message}" in capsys.readouterr().err, argv


def test_every_flag_has_help_and_its_default():
    parser = sweep.build_parser()
    for action in parser._actions:
        if action.dest != "help":
            assert action.help and "default" in action.help, action.option_strings


def test_presets_and_chunking():
    config = sweep.parse_args(["--preset", "paper", "--seeds", "2"]).config
    assert (config.iterations, config.seeds) == (5000, 2)  # explicit flags beat the preset
    assert chunks.blocks_per_chunk(30, 5) == 5
    assert chunks.blocks_per_chunk(30, 4) == 3
    assert chunks.blocks_per_chunk(7, 5) == 1


def test_a_damaged_demonstration_cache_is_made_again(demos_path, tmp_path, monkeypatch, capsys):
    from pngail_jax.config.run_config import RunConfig
    from pngail_jax.jobs.make_demos import MakeDemosConfig

    monkeypatch.setattr(demos_job, "DEMO_CACHE", tmp_path)
    cached = tmp_path / "Pendulum-v1" / "demos.npz"
    cached.parent.mkdir()
    cached.write_bytes(demos_path.read_bytes()[:300])  # a truncated copy
    calls = []

    def fake_make(config, claim, continue_cut=False):  # stands in for minutes of TRPO
        calls.append((config, claim.directory, claim.overwrite, continue_cut))
        shutil.copy(demos_path, cached)

    monkeypatch.setattr(demos_job, "make_claimed", fake_make)
    demos, path = demos_job.load_or_make_demos(RunConfig(env="Pendulum-v1"))
    printed = capsys.readouterr().out
    assert "the cached demonstrations are damaged" in printed and str(cached) in printed
    # The making's defaults (the command line's), over the runner's own damaged cache (a
    # making of the same config cut short there would continue).
    assert calls == [(MakeDemosConfig(env="Pendulum-v1"), tmp_path / "Pendulum-v1", True, True)]
    assert demos.num_rows == 100 and path == str(cached.absolute())


def test_out_naming_a_file_is_refused(tmp_path, capsys):
    a_file = tmp_path / "results.txt"
    a_file.write_text("mine")
    with pytest.raises(SystemExit, match="^2$"):
        sweep.parse_args(["--out", str(a_file)])
    assert f"--out {a_file} is a file, not a directory" in capsys.readouterr().err
    assert a_file.read_text() == "mine"


def test_a_finished_run_resumes_to_already_complete_and_a_held_run_is_refused(
    finished, tmp_path, capsys
):
    import os

    from pngail_jax.storage.outputs import LOCK

    out = copy_run(finished, tmp_path)
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}
    sweep.main(["--resume", str(out)])
    printed = capsys.readouterr().out
    assert "already complete; nothing to do" in printed and "compiling" not in printed
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()} == before
    (out / LOCK).write_text(json.dumps({"pid": os.getpid(), "host": os.uname().nodename}))
    with pytest.raises(SystemExit, match=rf"cannot run: {out} is in use by .* {os.getpid()}"):
        sweep.main(["--resume", str(out)])
    (out / LOCK).unlink()


def test_outputs_never_claim_more_than_the_checkpoints_hold(finished, tmp_path, capsys):
    """A finished run whose checkpoints were deleted starts again; its old outputs, which
    claim the whole run, are removed first, and the run ends with the same numbers."""
    out = copy_run(finished, tmp_path)
    shutil.rmtree(out / "checkpoints")
    (out / "metrics.csv").unlink()  # an output missing: not "already complete"
    sweep.main(["--resume", str(out)])
    printed = capsys.readouterr().out
    assert "the outputs say 4 iterations, the checkpoint holds 0: removing" in printed
    assert metrics_numbers(out / "metrics.csv") == metrics_numbers(finished / "metrics.csv")
    assert json.loads((out / "summary.json").read_text())["complete"]


@pytest.mark.parametrize(
    ("field", "value", "named"),
    [
        ("config.label_ratios", [0.1], "config.label_ratios: was [0.2], now [0.1]"),
        ("config.iterations", 8, "config.iterations: was 4, now 8"),
        ("resolved.demos_path", "/elsewhere/demos.npz", "resolved.demos_path: was "),
    ],
)
def test_a_hand_edited_config_is_refused_naming_the_field(finished, tmp_path, field, value, named):
    out = copy_run(finished, tmp_path)
    (out / "metrics.csv").unlink()  # not "already complete": the resume would train
    config = json.loads((out / "config.json").read_text())
    where = config
    *parents, key = field.split(".")
    for parent in parents:
        where = where[parent]
    where[key] = value
    (out / "config.json").write_text(json.dumps(config))
    with pytest.raises(SystemExit, match="config.json was changed since the run began") as error:
        sweep.main(["--resume", str(out)])
    assert named in str(error.value)
    original = json.loads((finished / "config.json").read_text())
    original["provenance"]["git_commit"] = "edited"  # where it ran is not sealed
    assert sealed_differences(out / record.SEAL, sealed_part(original)) == []


def test_a_damaged_seal_is_refused(finished, tmp_path):
    out = copy_run(finished, tmp_path)
    seal = out / record.SEAL
    seal.write_text(seal.read_text().replace("0.2", "0.3"))
    with pytest.raises(SystemExit, match=r"\.config\.sealed\.json: damaged"):
        sweep.main(["--resume", str(out)])
    seal.unlink()  # a copy without its dot-files, or a run from before seals: refused
    with pytest.raises(SystemExit, match=r"its seal \.config\.sealed\.json is missing"):
        sweep.main(["--resume", str(out)])
    (out / MARKER).unlink()  # a run from before the marker too: the same
    with pytest.raises(SystemExit, match="pass --allow-unsealed to go on unchecked"):
        sweep.main(["--resume", str(out)])


def test_a_full_disk_while_checkpointing_is_one_line_and_leaves_no_half_checkpoint(
    tmp_path, monkeypatch
):
    import errno

    def full(directory, tree):
        Path(directory).mkdir(parents=True)  # orbax got as far as its folder
        (Path(directory).parent.parent / "x.orbax-checkpoint-tmp-1").mkdir()
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(chunks, "save_tree", full)
    progress = chunks.Progress(3, {}, {"eval/return": np.zeros((1, 2))}, {"seconds": 1.0})
    with pytest.raises(
        chunks.RunError, match=r"cannot write checkpoint .*chunk_0003: No space left"
    ):
        chunks.save_checkpoint(tmp_path / "checkpoints", progress, {}, writer=True)
    assert not any((tmp_path / "checkpoints").iterdir())  # no chunk_0003, no orbax temporary


HOLD_THE_CACHE = """
import shutil, sys, time
from pathlib import Path
from pngail_jax.storage.outputs import claimed

cache, made = Path(sys.argv[1]), sys.argv[2]
with claimed(cache, "make_demos", overwrite=True) as claim:
    claim.prepare()
    print("holding", flush=True)
    time.sleep(2)
    shutil.copy(made, cache / "demos.npz")
"""


def test_a_second_sweep_waits_for_the_demonstrations_another_process_makes(
    demos_path, tmp_path, monkeypatch, capsys
):
    """Two real processes on one demonstrations cache: the second waits (one line naming the
    first), then reuses what the first made instead of making them again."""
    import subprocess
    import sys

    from pngail_jax.config.run_config import RunConfig
    from pngail_jax.storage import outputs

    monkeypatch.setattr(demos_job, "DEMO_CACHE", tmp_path)
    monkeypatch.setattr(outputs, "WAIT_SECONDS", 0.1)

    def made_twice(config, claim, **_):
        raise AssertionError("the demonstrations were made a second time")

    monkeypatch.setattr(demos_job, "make_claimed", made_twice)
    cache = tmp_path / "Pendulum-v1"
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD_THE_CACHE, str(cache), str(demos_path)],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "holding"
        demos, path = demos_job.load_or_make_demos(RunConfig(env="Pendulum-v1"))
    finally:
        holder.wait(timeout=60)
    printed = capsys.readouterr().out
    waiting = [line for line in printed.splitlines() if line.startswith("waiting:")]
    assert len(waiting) == 1, printed
    assert f"in use by experiments.make_demos, process {holder.pid}" in waiting[0]
    assert "reusing demonstrations" in printed
    assert demos.num_rows == 100 and path == str((cache / "demos.npz").absolute())


def test_the_demonstrations_cache_is_a_setting(tmp_path, monkeypatch):
    monkeypatch.delenv(demos_job.DEMO_CACHE_VARIABLE, raising=False)
    assert demos_job.demos_cache() == demos_job.DEMO_CACHE == Path("runs") / "demos-cache"
    monkeypatch.setenv(demos_job.DEMO_CACHE_VARIABLE, str(tmp_path / "cache"))
    assert demos_job.demos_cache() == tmp_path / "cache"


def test_a_sigterm_ends_the_sweep_in_one_line(demos_path, tmp_path, monkeypatch):
    from pngail_jax.jobs import sweep as sweep_job

    monkeypatch.setattr(sweep_job, "run", sigterm_to_self)
    with pytest.raises(SystemExit, match="interrupted before the run began: nothing was written"):
        sweep.main(tiny_sweep_args(demos_path, tmp_path / "run"))


def test_a_signal_during_a_chunk_stops_the_sweep_once_that_chunk_is_saved(
    finished, demos_path, tmp_path, monkeypatch, capsys
):
    """A signal reaches Python only when the compiled chunk returns: the chunk is kept (its
    checkpoint and partial outputs written) before the sweep stops, and --resume ends with
    the uninterrupted run's numbers."""
    from pngail_jax.grid import Grid

    run_chunk = Grid.run_chunk

    def signalled(self, state):
        result = run_chunk(self, state)
        sigterm_to_self(wait=0.1)  # arrives as the chunk returns
        return result

    out = tmp_path / "run"
    monkeypatch.setattr(Grid, "run_chunk", signalled)
    with pytest.raises(SystemExit, match=f"interrupted: finished chunks are kept; --resume {out}"):
        sweep.main(tiny_sweep_args(demos_path, out))
    assert "SIGTERM: the run stops once this chunk is saved" in capsys.readouterr().err
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["chunk_0001"]
    assert len(read_csv(out / "metrics.csv")) == 2 * 2 * 2  # methods x seeds x 2 iterations
    monkeypatch.setattr(Grid, "run_chunk", run_chunk)
    sweep.main(["--resume", str(out)])
    assert metrics_numbers(out / "metrics.csv") == metrics_numbers(finished / "metrics.csv")


# -- run records (pngail_jax.analysis.run_records), on this module's finished run: no new compile


def test_a_record_keeps_the_run_small_and_checks_itself(finished, tmp_path, capsys):
    """experiments.record writes config, command, commit, machine and the gzipped metrics,
    reads them back, and recomputes both statistics (the late average, the headline, and the
    final evaluation); --check finds each kind of damage."""
    import gzip

    from pngail_jax.programs import record as program

    [folder] = program.main([str(finished), "--name", "tiny", "--records", str(tmp_path)])
    assert folder == tmp_path / "tiny"
    assert sorted(p.name for p in folder.iterdir()) == ["metrics.csv.gz", "record.json"]
    record = json.loads((folder / "record.json").read_text())
    config = json.loads((finished / "config.json").read_text())
    assert record["config"] == {k: v for k, v in config.items() if k != "provenance"}
    assert record["command"] == config["provenance"]["command_line"]
    assert record["command"][:3] == ["python", "-m", "experiments.sweep"]  # runs as written
    assert sweep.build_parser().parse_args(record["command"][3:]).out == finished
    assert record["commit"] == config["provenance"]["git_commit"]
    assert record["machine"]["cpu_model"] and record["complete"] is True
    assert record["iterations_done"] == record["iterations"] == 4
    summary = json.loads((finished / "summary.json").read_text())
    assert record["late_share"] == 0.2 and record["format"] == 3 and record["unsealed"] is False
    for key in ("final_normalized_return", "late_average_normalized_return"):
        for method, values in record[key].items():
            # metrics.csv keeps 6 significant digits; the summary, the full float.
            assert len(values) == 2 and np.mean(values) == pytest.approx(
                summary["methods"][method][f"{key}_mean"], rel=1e-5, abs=1e-6
            )
    # each seed's classifier error as the summary states it (not in metrics.csv)
    assert record["confidence_mae"] == {
        method: [seed["confidence_mae"] for seed in row["per_seed"]]
        for method, row in summary["methods"].items()
    }
    assert all(isinstance(v, float) for v in record["confidence_mae"]["pngail"])
    with gzip.open(folder / "metrics.csv.gz", "rt") as file:
        assert file.read() == (finished / "metrics.csv").read_text()
    assert "ok  tiny: Pendulum-v1, 2 methods, 4 runs, complete" in (
        program.main(["--check", str(folder)]) and capsys.readouterr().out
    )
    # The same run recorded again gives the same bytes; a folder of other files is refused.
    program.main([str(finished), "--name", "tiny", "--records", str(tmp_path)])
    assert json.loads((folder / "record.json").read_text()) == record
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(SystemExit, match="holds files a record does not .notes.txt."):
        program.main([str(finished), "--name", "other", "--records", str(tmp_path)])


def write_edited(folder, record, reseal=True):
    """A record.json edited by hand: with ``reseal``, its digest made again, as a careful
    forger would (so that the checks behind the digest are what refuses it)."""
    from pngail_jax.analysis import run_records

    edited = run_records.sealed_record(record) if reseal else record
    (folder / "record.json").write_text(json.dumps(edited))


def test_record_check_finds_each_kind_of_damage(finished, tmp_path):
    """--check refuses a changed metrics file, an edited record (by its digest), an edited
    stated return or late share behind a remade digest, and a cell cut out; a folder without
    a run is named."""
    import gzip

    from pngail_jax.analysis import run_records
    from pngail_jax.programs import record as program

    [folder] = program.main([str(finished), "--name", "tiny", "--records", str(tmp_path)])
    record = json.loads((folder / "record.json").read_text())
    good = (folder / "metrics.csv.gz").read_bytes()
    (folder / "metrics.csv.gz").write_bytes(good[:-10])
    with pytest.raises(SystemExit, match="metrics.csv.gz differs from what the record wrote"):
        program.main(["--check", str(folder)])
    (folder / "metrics.csv.gz").write_bytes(good)
    for field, value in (("commit", "0" * 40), ("command", ["python", "-m", "x"])):
        write_edited(folder, {**record, field: value}, reseal=False)
        with pytest.raises(SystemExit, match="record.json was changed since it was written"):
            program.main(["--check", str(folder)])
    for key in ("final_normalized_return", "late_average_normalized_return"):
        edited = json.loads(json.dumps(record))
        first = next(iter(edited[key]))
        edited[key][first][0] += 0.5
        write_edited(folder, edited)
        with pytest.raises(SystemExit, match=f"its {key} differs from that of metrics.csv"):
            program.main(["--check", str(folder)])
    for errors in ({"pngail": [0.1]}, {"icgail": [0.1, 0.2]}, {"pngail": ["0.1", 0.2]}):
        write_edited(folder, {**record, "confidence_mae": errors})
        with pytest.raises(SystemExit, match="confidence_mae is not one number per seed"):
            program.main(["--check", str(folder)])
    write_edited(folder, {**record, "late_share": 0.1})
    with pytest.raises(SystemExit, match="last 0.1 of training, this version's over 0.2"):
        program.main(["--check", str(folder)])
    text = (finished / "metrics.csv").read_text().splitlines(keepends=True)
    cut = gzip.compress("".join(text[:-4]).encode(), mtime=0)
    (folder / "metrics.csv.gz").write_bytes(cut)
    record["metrics"] |= {"bytes": len(cut), "sha256": f"sha256:{hashlib.sha256(cut).hexdigest()}"}
    write_edited(folder, record)
    with pytest.raises(run_records.RecordError, match="pngail has seeds 2, its metrics.csv.gz 1"):
        run_records.check_record(folder)
    with pytest.raises(SystemExit, match="holds no sweep or offline run"):
        program.main([str(tmp_path), "--name", "x", "--records", str(tmp_path / "r")])


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda c, r: c["config"].update(label_ratios=[0.4]), r"label ratios \[0.4\], its metrics"),
        (
            lambda c, r: c["config"].update(noise_stds=[0.1]),
            r"confidence noises \[0.1\], its metrics",
        ),
        (
            lambda c, r: c["config"].update(iterations=40),
            "config plans 40 and its metrics.csv.gz ends at 4",
        ),
        (lambda c, r: r.update(iterations_done=3), "iterations done 3, its metrics.csv.gz 4"),
        (lambda c, r: r.update(complete=False), "complete: False"),
        (lambda c, r: c["config"].update(seeds=3), "gail has seeds 3, its metrics.csv.gz 2"),
        (lambda c, r: c["config"].update(methods=["gail"]), r"methods \['gail'\], its metrics"),
        (
            lambda c, r: c["config"]["settings"].update(num_envs=5),
            "250 environment steps an iteration",
        ),
        (
            lambda c, r: c["resolved"].update(return_range=[-1300.0, -100.0]),
            "normalised return .* is not its evaluation .* through the run's return range",
        ),
    ],
    ids=["label_ratios", "noise", "iterations", "done", "complete", "seeds", "methods",
         "steps", "return_range"],
)  # fmt: skip
def test_record_check_recomputes_its_config_from_its_metrics(
    finished, tmp_path, edit, message, capsys
):
    """A record's config facts (task, methods, seeds, label ratios and noises, iterations done
    and planned, completeness, steps per iteration, return range) edited with the digest made
    again are refused, each naming what its metrics say; the record itself passes."""
    from pngail_jax.programs import record as program

    [folder] = program.main([str(finished), "--name", "tiny", "--records", str(tmp_path)])
    record = json.loads((folder / "record.json").read_text())
    record.pop("digest")
    edit(record["config"], record)
    write_edited(folder, record)
    with pytest.raises(SystemExit, match=message) as refused:
        program.main(["--check", str(folder)])
    assert "\n" not in str(refused.value.code)


def test_a_records_task_is_that_of_its_authors_file_and_return_range(tmp_path):
    """The task of a record on an authors' file (the paper's Table 3 return range, which its
    scores agree with) cannot be changed, even with the digest made again. (On a made set
    the task has no witness in the metrics: the digest alone keeps it.)"""
    from pngail_jax.programs import record as program

    folder = tmp_path / "offline-pendulum"
    shutil.copytree(Path(__file__).parents[1] / "records" / "offline-pendulum", folder)
    program.main(["--check", str(folder)])
    record = json.loads((folder / "record.json").read_text())
    record["config"]["config"]["env"] = "HalfCheetah-v4"
    write_edited(folder, record)
    with pytest.raises(SystemExit, match="the task is HalfCheetah-v4, its demonstrations and "
                       "return range .* are Pendulum-v1's"):  # fmt: skip
        program.main(["--check", str(folder)])


def iqm_by_hand(values) -> float:
    """The interquartile mean as rliable defines it: sort, drop int(k / 4) values from each
    end, average the rest."""
    ordered = np.sort(np.asarray(values, float))
    cut = ordered.size // 4
    return float(ordered[cut : ordered.size - cut].mean())


def test_rerun_spread_is_the_95th_percentile_of_the_iqm_shifts_of_draws():
    """run_records.rerun_spread against its definition, redone here with NumPy alone: the
    95th percentile of |IQM(k of the record's seeds, drawn without replacement) - IQM(all)|
    over 2,000 draws of np.random.default_rng(0); and cases whose answer is known exactly."""
    from pngail_jax.analysis import run_records

    ten = [k / 10 for k in range(10)]
    assert iqm_by_hand(ten) == pytest.approx(0.45)  # 10 seeds: 2 cut each end, 0.2..0.7 kept
    assert iqm_by_hand([0.3, 0.0, 0.9, 0.6, 0.1]) == pytest.approx(1 / 3)  # 0.1, 0.3, 0.6
    rng = np.random.default_rng(0)
    shifts = [
        abs(iqm_by_hand(rng.choice(ten, 5, replace=False)) - iqm_by_hand(ten)) for _ in range(2000)
    ]
    expected = np.percentile(shifts, 95)
    assert run_records.rerun_spread(ten, 5) == pytest.approx(expected, rel=1e-12)
    # Without the random stream: over all 252 draws of 5 of the 10, enumerated, the 95th
    # percentile of the shifts is 13/60 too (the shifts take few values; the largest is 0.25).
    every_draw = [abs(iqm_by_hand(draw) - 0.45) for draw in itertools.combinations(ten, 5)]
    assert np.percentile(every_draw, 95) == pytest.approx(13 / 60)
    assert expected == pytest.approx(13 / 60)
    # Seeds that are not numbers are left out before drawing: the same draws, the same spread.
    assert run_records.rerun_spread([*ten, None, float("nan")], 5) == pytest.approx(
        expected, rel=1e-12
    )
    # Every seed the same: every draw's IQM is the record's, the spread 0.
    assert run_records.rerun_spread([0.5] * 10, 5) == 0.0
    # One seed of four drawn from [0, 0, 0, 1] (IQM 0, the middle two): a shift of 1 a quarter
    # of the time, about 500 of 2,000 draws, far above the top 5% (100): the percentile is 1.
    assert run_records.rerun_spread([0.0, 0.0, 0.0, 1.0], 1) == 1.0
    # No more seeds than the re-run's (or none re-run): no draw differs from the record.
    for num_seeds in (5, 6, 0):
        assert np.isnan(run_records.rerun_spread(ten[:5], num_seeds)), num_seeds


def test_a_record_made_unsealed_says_so(finished, tmp_path, capsys):
    """A record of a run without its seal (--allow-unsealed) keeps that in record.json and
    --check says it on its line."""
    from pngail_jax.programs import record as program

    copy = copy_run(finished, tmp_path)
    (copy / record.SEAL).unlink()
    [folder] = program.main([str(copy), "--name", "loose", "--records", str(tmp_path / "r"),
                             "--allow-unsealed"])  # fmt: skip
    assert json.loads((folder / "record.json").read_text())["unsealed"] is True
    capsys.readouterr()
    program.main(["--check", str(folder)])
    assert "made with --allow-unsealed (its run's config.json unchecked)" in capsys.readouterr().out


def test_a_record_of_the_format_before_is_upgraded_once_it_checks(finished, tmp_path):
    """--check names --upgrade for a format-2 record; --upgrade adds the digest after checking
    the record whole, and leaves a record that does not check as it was."""
    from pngail_jax.programs import record as program

    [folder] = program.main([str(finished), "--name", "old", "--records", str(tmp_path)])
    record = json.loads((folder / "record.json").read_text())
    old = {k: v for k, v in record.items() if k not in ("digest", "unsealed")} | {"format": 2}
    (folder / "record.json").write_text(json.dumps(old))
    with pytest.raises(SystemExit, match="not a run record of format 3: bring it up to date "
                       f"with python -m experiments.record --upgrade {folder}"):  # fmt: skip
        program.main(["--check", str(folder)])
    program.main(["--upgrade", str(folder)])
    upgraded = json.loads((folder / "record.json").read_text())
    assert upgraded == {**record, "unsealed": None, "digest": upgraded["digest"]}
    program.main(["--check", str(folder)])
    bad = json.loads(json.dumps(old))
    bad["final_normalized_return"]["gail"][0] += 0.5
    (folder / "record.json").write_text(json.dumps(bad))
    before = (folder / "record.json").read_bytes()
    with pytest.raises(SystemExit, match="its final_normalized_return differs"):
        program.main(["--upgrade", str(folder)])
    assert (folder / "record.json").read_bytes() == before


def edit_metrics(run, change):
    """``change(row)`` applied to every row of ``run``'s metrics.csv (a dict per row)."""
    path = run / "metrics.csv"
    rows = read_csv(path)
    for row in rows:
        change(row)
    with path.open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def verification_cases(random_return: float, optimal_return: float) -> list:
    """(damage to a finished run, the refusal it must give) pairs for
    ``test_the_verification_reads_every_number_it_passes_on``."""

    def both(iteration, value):
        def change(row):
            if (row["method"], row["seed"], row["iteration"]) == ("pngail", "1", iteration):
                row["eval_return"] = f"{value:.6g}"
                row["normalized_return"] = (
                    f"{(value - random_return) / (optimal_return - random_return):.6g}"
                )

        return change

    def alone(row):
        if (row["method"], row["seed"], row["iteration"]) == ("gail", "0", "4"):
            row["normalized_return"] = "0.9"

    def edited_under_the_old_key(summary):
        del summary["return_range"]
        summary["normalizer"] = [-1000.0, 0.0]

    def summary_edit(run, edit):
        path = run / "summary.json"
        summary = json.loads(path.read_text())
        edit(summary)
        path.write_text(json.dumps(summary))

    cases = [
        (lambda run: edit_metrics(run, alone),
         r"metrics.csv: gail seed 0 iteration 4: normalised return 0.9 is not its evaluation"),
        (lambda run: edit_metrics(run, both("2", -150.0)),
         r"summary.json gives pngail seed 1 average_return .* \(iterations 1-4\)"),
        (lambda run: edit_metrics(run, both("4", -150.0)),
         r"summary.json says pngail seed 1 ended at .* \(iteration 4\)"),
        (lambda run: summary_edit(run, lambda s: s["methods"]["gail"]["per_seed"][0].update(
            late_average_normalized_return=0.7)),
         r"summary.json gives gail seed 0 late_average_normalized_return 0.7, metrics.csv's "
         r"evaluations \(iteration 4\)"),
        (lambda run: summary_edit(run, lambda s: s.update(return_range=[-1000.0, 0.0])),
         r"summary.json's return range \[-1000.0, 0.0\] is not config.json's"),
        # A summary.json written before "return_range" had its name says "normalizer".
        (lambda run: summary_edit(run, edited_under_the_old_key),
         r"summary.json's return range \[-1000.0, 0.0\] is not config.json's"),
    ]  # fmt: skip
    return cases


def test_the_verification_reads_every_number_it_passes_on(finished, tmp_path):
    """Every program that reads a run (compare, record, resume) refuses, in one line naming
    the file, method, seed and iteration: a normalised return edited alone; evaluations
    edited in both columns, consistently, before the last (the training average no longer
    the summary's) or at it (the final return no longer the summary's); a late average edited
    in summary.json; a return range edited in summary.json."""
    from pngail_jax.programs import compare as compare_program
    from pngail_jax.programs import record as record_program

    config = json.loads((finished / "config.json").read_text())
    random_return, optimal_return = config["resolved"]["return_range"]

    cases = verification_cases(random_return, optimal_return)
    for index, (damage, message) in enumerate(cases):
        run = tmp_path / f"run{index}"
        shutil.copytree(finished, run)
        damage(run)
        for program, argv in (
            (compare_program, [str(run), "--out", str(tmp_path / f"cmp{index}")]),
            (record_program, [str(run), "--name", "r", "--records", str(tmp_path / "rec")]),
            (sweep, ["--resume", str(run)]),
        ):
            with pytest.raises(SystemExit, match=message) as refused:
                program.main(argv)
            assert "\n" not in str(refused.value.code), refused.value.code
        assert not (tmp_path / f"cmp{index}").exists() and not (tmp_path / "rec").exists()


def test_a_summary_written_before_return_range_had_its_name_reads(finished, tmp_path):
    """A new summary.json names the normalised return's ends "return_range"; one written
    before says "normalizer", and compare and record read that run as they read a new one."""
    import shutil

    from pngail_jax.analysis.report import summary_return_range
    from pngail_jax.programs import compare as compare_program
    from pngail_jax.programs import record as record_program

    summary = json.loads((finished / "summary.json").read_text())
    config = json.loads((finished / "config.json").read_text())
    assert "normalizer" not in summary
    assert summary["return_range"] == config["resolved"]["return_range"]
    # Whether a wrong range under the old key is read is the verification test's last case;
    # here every program that reads a run gets through one (a reader asking for the new key
    # alone would fail here).
    run = tmp_path / "old-summary"
    shutil.copytree(finished, run)
    old = {
        ("normalizer" if key == "return_range" else key): value for key, value in summary.items()
    }
    (run / "summary.json").write_text(json.dumps(old))
    assert summary_return_range(old) == (True, summary["return_range"])
    assert summary_return_range({"methods": {}}) == (False, None)
    compare_program.main([str(run), "--out", str(tmp_path / "compared")])
    assert (tmp_path / "compared").is_dir()
    [folder] = record_program.main([str(run), "--name", "old", "--records", str(tmp_path / "r")])
    assert (folder / "record.json").is_file()


def test_compare_expected_says_where_a_run_lies_against_a_record(finished, tmp_path):
    """compare --expected: a run against its own record lies within every interval; made-up
    scores below and above the record's interval are named so, with the distance; a record
    of another task is refused."""
    from pngail_jax.analysis import run_records
    from pngail_jax.analysis.compare import Scores
    from pngail_jax.config.run_config import RunConfig
    from pngail_jax.programs import compare as compare_program
    from pngail_jax.programs import record as record_program

    defaults = RunConfig().to_dict()  # what compare passes for a sweep
    [folder] = record_program.main([str(finished), "--name", "r", "--records", str(tmp_path)])
    out = compare_program.main([str(finished), "--expected", str(folder),
                                "--out", str(tmp_path / "cmp")])  # fmt: skip
    expected = json.loads((out / "compare.json").read_text())["expected"]
    assert expected["config_differences"] == []
    assert [row["verdict"] for row in expected["rows"]] == ["within", "within"]
    assert "## Against the record r (Pendulum-v1" in (out / "compare.md").read_text()
    record = run_records.check_record(folder)
    record["late_average_normalized_return"] = {"gail": [0.4, 0.5, 0.6], "pngail": [0.8, 0.9, 1.0]}
    scores = Scores({"gail": {"Pendulum-v1": np.array([0.1, 0.2, 0.15])}})
    rows = run_records.expected_rows(scores, record)
    assert rows[0]["verdict"] == "below" and rows[0]["outside_by"] == pytest.approx(
        rows[0]["reference_ci95"][0] - 0.15
    )
    assert rows[1]["verdict"] == "not in your runs"
    high = Scores({"gail": {"Pendulum-v1": np.array([0.9, 0.95, 1.0])}})
    assert run_records.expected_rows(high, record)[0]["verdict"] == "above"
    other = Scores({"gail": {"Hopper-v4": np.array([0.5])}})
    with pytest.raises(run_records.RecordError, match="is of Pendulum-v1; your runs are of Hopper"):
        run_records.expected_rows(other, record)
    document, fields = record["config"], record["config"]["config"]

    def with_fields(**changes):  # the record's config.json with these config fields
        return {**document, "config": {**fields, **changes}}

    changed = with_fields(iterations=8, log=["x"])
    assert run_records.config_differences(changed, record, defaults) == ["iterations"]
    # a field the record's run did not have yet is its default there
    without_seed = {k: v for k, v in fields.items() if k != "seed"}
    older = {**record, "config": {**document, "config": without_seed}}
    assert run_records.config_differences(document, older, defaults) == []
    assert run_records.config_differences(with_fields(seed=3), older, defaults) == ["seed"]
    # a record of the sweep's flat layout before runs.run_document, and before the learner
    # part (flat learner, fisher, value_epochs, no PPO settings), reads as what it ran:
    # today's run of the same settings does not differ
    flat = {k: v for k, v in fields.items() if k != "learner"}
    flat.update(learner="trpo", fisher="gauss_newton", fisher_subsample=1, value_epochs=1)
    flat_record = {**record, "config": {**flat, "resolved": document["resolved"]}}
    assert run_records.config_differences(document, flat_record, defaults) == []
    more_epochs = json.loads(json.dumps(document))
    more_epochs["config"]["learner"]["trpo"]["num_value_epochs"] = 3
    assert run_records.config_differences(more_epochs, flat_record, defaults) == ["learner"]
    # A record of seeds 0.0-0.9 (IQM 0.45): a 5-seed re-run's IQM lands within 13/60 of it
    # (test_rerun_spread_is_the_95th_percentile_of_the_iqm_shifts_of_draws).
    ten = [k / 10 for k in range(10)]
    record["late_average_normalized_return"] = {"gail": ten}
    near = Scores({"gail": {"Pendulum-v1": np.array([0.3, 0.4, 0.5, 0.6, 0.55])}})
    far = Scores({"gail": {"Pendulum-v1": np.array([0.9, 0.95, 1.0, 0.97, 0.99])}})
    assert run_records.expected_rows(near, record)[0]["within_rerun_spread"]
    assert not run_records.expected_rows(far, record)[0]["within_rerun_spread"]
    rows = run_records.expected_rows(far, record)
    table = run_records.expected_markdown(rows, record, [], "late_average")
    assert "beyond the spread a re-run of 5 seeds shows" in table
    assert "Score: normalised return, mean over the last 20% of training." in table
    # --statistic final reads the record's final evaluations, not its late averages
    record["final_normalized_return"] = {"gail": [0.9, 1.0, 0.95, 0.97, 0.99, 0.98]}
    assert (
        run_records.expected_rows(Scores(far.values, statistic="final"), record)[0]["verdict"]
        == "within"
    )


def test_compare_expected_compares_like_with_like(finished, demos_path, tmp_path, monkeypatch):
    """compare --expected says when either side is unfinished and compares only runs at the
    record's iterations: a run stopped at 2 of 4 iterations is refused against the finished
    record (not "below by ..."), and set against a record of itself it is compared with a
    note saying both are unfinished; a run of another program than the record's is refused."""
    from pngail_jax.programs import compare as compare_program
    from pngail_jax.programs import record as record_program

    [whole] = record_program.main([str(finished), "--name", "whole", "--records",
                                   str(tmp_path / "r")])  # fmt: skip
    partial = tmp_path / "partial"
    killed_at_the_second_checkpoint = killed_at_checkpoint(2)
    monkeypatch.setattr(chunks, "save_checkpoint", killed_at_the_second_checkpoint)
    with pytest.raises(Killed):
        sweep.main(tiny_sweep_args(demos_path, partial))
    monkeypatch.undo()
    with pytest.raises(SystemExit, match=f"{partial} reached 2 of 4 iterations, the record whole "
                       "4 of 4: compare like with like"):  # fmt: skip
        compare_program.main([str(partial), "--expected", str(whole),
                              "--out", str(tmp_path / "c1")])  # fmt: skip
    assert not (tmp_path / "c1").exists()
    [cut] = record_program.main([str(partial), "--name", "cut", "--records", str(tmp_path / "r")])
    out = compare_program.main([str(partial), "--expected", str(cut),
                                "--out", str(tmp_path / "c2")])  # fmt: skip
    text = (out / "compare.md").read_text()
    assert "Note: the record cut is unfinished: 2 of 4 iterations." in text
    assert f"Note: {partial} is unfinished: 2 of 4 iterations." in text
    offline_record = Path(__file__).parents[1] / "records" / "offline-pendulum"
    with pytest.raises(SystemExit, match=f"{finished} is a run of experiments.sweep, the record "
                       "offline-pendulum of experiments.offline"):  # fmt: skip
        compare_program.main([str(finished), "--expected", str(offline_record),
                              "--out", str(tmp_path / "c3")])  # fmt: skip


def test_every_program_that_reads_a_run_verifies_it_the_same_way(finished, tmp_path, capsys):
    """resume, compare and record trust a run only as runs.verify_run does: a summary.json
    edited by hand, a config.json edited by hand and a run copied without its seal are each
    refused in one line naming the file; --allow-unsealed goes on and says what it skipped."""
    from pngail_jax.programs import compare as compare_program
    from pngail_jax.programs import record as record_program

    copy = copy_run(finished, tmp_path)

    def refused(program, argv):
        with pytest.raises(SystemExit) as stop:
            program.main(argv)
        assert "Traceback" not in str(stop.value.code)
        return str(stop.value.code)

    compare_argv = [str(copy), "--out", str(tmp_path / "cmp")]
    record_argv = [str(copy), "--name", "r", "--records", str(tmp_path / "records")]
    summary = json.loads((copy / "summary.json").read_text())
    edited = json.loads(json.dumps(summary))
    edited["methods"]["gail"]["per_seed"][1]["final_return"] += 100.0
    (copy / "summary.json").write_text(json.dumps(edited))
    for program, argv in ((compare_program, compare_argv), (record_program, record_argv),
                          (sweep, ["--resume", str(copy)])):  # fmt: skip
        assert "summary.json says gail seed 1 ended at" in refused(program, argv)
    (copy / "summary.json").write_text(json.dumps(summary))
    config = json.loads((copy / "config.json").read_text())
    (copy / "config.json").write_text(json.dumps({**config, "iterations": 40}))
    for program, argv in ((compare_program, compare_argv), (record_program, record_argv)):
        assert "config.json was changed since the run began (iterations" in refused(program, argv)
    (copy / "config.json").write_text(json.dumps(config))
    (copy / record.SEAL).unlink()  # copied without its dot-files
    for program, argv in ((compare_program, compare_argv), (record_program, record_argv),
                          (sweep, ["--resume", str(copy)])):  # fmt: skip
        assert "its seal .config.sealed.json is missing" in refused(program, argv)
    out = compare_program.main([*compare_argv, "--allow-unsealed"])
    assert "**Checks let through**" in (out / "compare.md").read_text()
    record_program.main([*record_argv, "--allow-unsealed"])
    sweep.main(["--resume", str(copy), "--allow-unsealed"])
    printed = capsys.readouterr().out
    assert "no seal, config.json unchecked (--allow-unsealed)" in printed
    assert "the run is already complete; nothing to do" in printed
