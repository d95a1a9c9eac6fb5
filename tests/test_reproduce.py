"""experiments.record --reproduce (pngail_jax.programs.reproduce): a record's command run again
into a folder of its own, continued when cut, and checked against the record; and every
committed record's command parses as its program reads it today."""

from __future__ import annotations

import copy
import csv
import gzip
import importlib
import io
import json
import shutil
from pathlib import Path

import pytest
from conftest import tiny_sweep_args

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def tiny(demos_path, tmp_path_factory):
    """(records folder, the finished tiny sweep) with the sweep recorded as ``tiny``."""
    from pngail_jax.programs import record, sweep

    base = tmp_path_factory.mktemp("reproduce")
    run = base / "run"
    sweep.main(tiny_sweep_args(demos_path, run))
    record.main([str(run), "--name", "tiny", "--records", str(base / "records")])
    return base / "records", run


def shifted_copy(
    records: Path, folder: Path, method: str, shift: float, seed: int | None = None, source="tiny"
) -> None:
    """``records/<source>`` copied into ``folder`` with every evaluation of ``method`` (of its
    seed ``seed`` alone, if given) raised by ``shift`` normalised (its raw return with it),
    its scores, metrics digest and seal made again: a record that checks, of numbers no run
    gave."""
    from pngail_jax.analysis import run_records
    from pngail_jax.analysis.runs import STATISTICS, read_run_config, scores_of_metrics
    from pngail_jax.storage.integrity import file_digest

    name = folder.name
    shutil.copytree(records / source, folder)
    record = json.loads((folder / "record.json").read_text())
    low, high = read_run_config(record["config"]).return_range
    metrics = folder / "metrics.csv.gz"
    rows = list(csv.DictReader(io.StringIO(gzip.decompress(metrics.read_bytes()).decode())))
    for row in rows:
        chosen = seed is None or row["seed"] == str(seed)
        if row["method"] == method and chosen and row["normalized_return"]:
            value = float(row["eval_return"]) + shift * (high - low)
            row["eval_return"] = f"{value:.6g}"
            row["normalized_return"] = f"{(value - low) / (high - low):.6g}"
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    metrics.write_bytes(gzip.compress(text.getvalue().encode(), mtime=0))
    record |= {"name": name, "metrics": {"file": metrics.name, "bytes": metrics.stat().st_size,
                                         "sha256": file_digest(metrics)}}  # fmt: skip
    progress = (record["iterations_done"], record["iterations"])
    for statistic in STATISTICS:
        scores = scores_of_metrics(
            metrics, read_run_config(record["config"]).settings, progress, statistic
        )
        record[run_records.statistic_key(statistic)] = {
            label: [float(v) for v in values] for label, values in scores.items()
        }
    (folder / "record.json").write_text(json.dumps(run_records.sealed_record(record)))
    run_records.check_record(folder)


def test_a_rerun_agrees_with_its_record_and_a_changed_record_fails(
    tiny, tmp_path, monkeypatch, capsys
):
    """The record's command, run again in a fresh interpreter on this machine, gives every
    seed of the record to the last bit, so every method agrees (exit 0); run again, the
    finished re-run is checked, not trained again; against a record whose GAIL seeds are
    raised by 5 (normalised) the same re-run fails that method, below the record's interval,
    and the program exits 1."""
    from pngail_jax.programs import record

    records, _ = tiny
    monkeypatch.chdir(ROOT)  # the command is python -m experiments.sweep, from the checkout
    out = tmp_path / "rerun"
    assert record.main(["--reproduce", "tiny", "--records", str(records), "--out", str(out)]) == [
        out
    ]
    text = capsys.readouterr().out
    assert "running the record tiny's command: python -m experiments.sweep" in text
    assert "  agrees when: " in text and "this run: commit " in text
    assert "2 of 2 methods agree with the record tiny" in text, text
    assert text.count("every seed identical to the record's") == 2, text
    record.main(["--reproduce", "tiny", "--records", str(records), "--out", str(out)])
    assert f"{out} holds the finished re-run of tiny: checking it" in capsys.readouterr().out

    shifted_copy(records, tmp_path / "records" / "shifted", "gail", 5.0)
    with pytest.raises(SystemExit) as failed:
        record.main(["--reproduce", "shifted", "--records", str(tmp_path / "records"),
                     "--out", str(out)])  # fmt: skip
    assert failed.value.code == 1
    text = capsys.readouterr().out
    [gail] = [line for line in text.splitlines() if line.strip().startswith("gail ")]
    assert "DIFFERS" in gail and "below by" in gail and "seeds differ" in gail, gail
    assert "1 of 2 methods agree with the record shifted: not reproduced" in text


def test_a_cut_rerun_is_continued_and_a_foreign_folder_refused(tiny, tmp_path, capsys):
    """A re-run cut short is continued with --resume of its folder alone; a folder holding
    another config's run, another program's files or strangers is refused in one line, and
    nothing is run."""
    from pngail_jax.analysis import run_records
    from pngail_jax.programs import reproduce

    records, finished = tiny
    cut = tmp_path / "cut"
    shutil.copytree(finished, cut)
    summary = json.loads((cut / "summary.json").read_text())
    (cut / "summary.json").write_text(json.dumps(summary | {"complete": False,
                                                            "iterations_done": 2}))  # fmt: skip
    calls = []

    def finishes(program, argv):  # stands in for the program: the run ends as the record's
        calls.append((program, argv))
        shutil.copytree(finished, cut, dirs_exist_ok=True)
        return 0

    stopped = (
        r"^the re-run stopped \(exit status 3; its reason above\): the same command continues "
        rf"it in {cut}$"
    )
    with pytest.raises(run_records.RecordError, match=stopped):
        reproduce.reproduce("tiny", records, cut, run=lambda program, argv: 3)
    assert reproduce.reproduce("tiny", records, cut, run=finishes)
    assert calls == [("sweep", ["--resume", str(cut)])]
    assert "continuing the record tiny's command" in capsys.readouterr().out

    def never(program, argv):
        raise AssertionError("nothing may run")

    other = tmp_path / "other"
    shutil.copytree(finished, other)
    config = json.loads((other / "config.json").read_text())
    (other / "config.json").write_text(
        json.dumps(config | {"config": config["config"] | {"seeds": 3}})
    )
    strangers = tmp_path / "strangers"
    strangers.mkdir()
    (strangers / "mine.txt").write_text("x")
    for folder, message in (
        (other, "holds another run of experiments.sweep .its config differs from the record "
                "tiny's in: seeds.: choose another --out"),
        (strangers, "is not empty: it holds files it did not make .mine.txt."),
    ):  # fmt: skip
        with pytest.raises(run_records.RecordError, match=message) as refused:
            reproduce.reproduce("tiny", records, folder, run=never)
        assert "\n" not in str(refused.value)
    assert reproduce.plan({"name": "tiny"}, "sweep", ["--seeds", "2", "--out", "x",
                          "--overwrite"], tmp_path / "new") == (
        "run", ["--seeds", "2", "--out", str(tmp_path / "new")],
    )  # fmt: skip


def test_the_tolerance_is_the_last_bit_only_for_the_records_code_on_its_machine(monkeypatch):
    """Same code (equal commits, or commits between which no file of the package, entry points
    or examples changed) on the same CPU model, libraries, XLA_FLAGS, platform and devices:
    the last bit; anything else, or a commit with uncommitted changes, is another draw."""
    import subprocess

    from pngail_jax.programs.reproduce import bit_for_bit, same_code

    monkeypatch.chdir(ROOT)  # same_code asks this checkout's git
    machine = {"cpu_model": "X", "libraries": {"jax": "1"}, "xla_flags": "", "platform": "cpu",
               "device_count": 1}  # fmt: skip
    record = {"commit": "abc", "machine": machine}
    assert bit_for_bit(record, {**machine, "git_commit": "abc"})
    for change in ({"git_commit": "abc+dirty"}, {"cpu_model": "Y"}, {"xla_flags": "--x"},
                   {"device_count": 4}, {"git_commit": None}):  # fmt: skip
        assert not bit_for_bit(record, {**machine, "git_commit": "abc", **change}), change
    assert not same_code("abc+dirty", "abc+dirty") and not same_code(None, None)
    known = subprocess.run(["git", "cat-file", "-e", "65bcdfb^{commit}"], cwd=ROOT,
                           capture_output=True).returncode == 0  # fmt: skip
    if known:  # 30c6f3d added records/quick-pendulum only; 4a04976 changed config/saved.py
        assert same_code("65bcdfb", "30c6f3d") and not same_code("94010a0", "4a04976")


def test_bad_requests_are_one_line(tiny, capsys):
    """An unknown record names those there are; a comparison's record and flags that do not
    go with --reproduce are refused in one line."""
    from pngail_jax.programs import record

    records, _ = tiny
    with pytest.raises(
        SystemExit, match=r"^no record 'nope' in .* \(the records of runs there: tiny\)$"
    ):
        record.main(["--reproduce", "nope", "--records", str(records)])
    with pytest.raises(SystemExit, match="the record settings-ant-v4 is a comparison of "
                       "experiments.compare_settings; --reproduce checks the records of "
                       "experiments.sweep and experiments.offline runs"):  # fmt: skip
        record.main(["--reproduce", "settings-ant-v4", "--records", str(ROOT / "records")])
    for argv in (["--reproduce", "tiny", "--check"], ["--out", "x", "--check", "r"]):
        with pytest.raises(SystemExit):
            record.main(argv)
        assert len(capsys.readouterr().err.strip().splitlines()) == 1  # the error, in one line


def test_stored_commands_are_read_in_their_older_forms():
    """python -m offline (format 2's slip) and an installed pngail-<program> read as python -m
    experiments.<program>; a command of no program of the package is refused."""
    from pngail_jax.analysis.run_records import RecordError
    from pngail_jax.programs.reproduce import rerun_arguments, stored_command

    def command(*words):
        return {"name": "r", "command": list(words)}

    assert stored_command(command("python", "-m", "offline", "--seeds", "5")) == (
        "offline", ["--seeds", "5"],
    )  # fmt: skip
    assert stored_command(command("pngail-compare-settings", "--env", "Ant-v4")) == (
        "compare_settings", ["--env", "Ant-v4"],
    )  # fmt: skip
    assert stored_command(command("python3", "-m", "experiments.sweep")) == ("sweep", [])
    for bad in (command("rm", "-rf", "/"), command("python", "-m", "os"), {"name": "r"}):
        with pytest.raises(RecordError, match="the record r"):
            stored_command(bad)
    words = ["--out=a", "--resume", "b", "--seeds", "2", "--overwrite"]
    assert rerun_arguments(words, Path("o")) == ["--seeds", "2", "--out", "o"]


@pytest.mark.parametrize(
    "folder", sorted(ROOT.glob("records/*/record.json")), ids=lambda p: p.parent.name
)
def test_every_committed_records_command_runs_as_written(folder, tmp_path, monkeypatch):
    """Each committed record's command, its --out pointed into tmp_path, is read by its
    program's flags; where every file it names is here (the authors' files beside the
    checkout), its program's own checks pass too (parse only: nothing trains)."""
    from pngail_jax.programs.reproduce import rerun_arguments, stored_command

    monkeypatch.chdir(ROOT)
    monkeypatch.syspath_prepend(str(ROOT))  # examples.*:preset methods, as python -m finds them
    record = json.loads(folder.read_text())
    program, argv = stored_command(record)
    assert record["command"][:3] == ["python", "-m", f"experiments.{program}"]  # as stored
    module = importlib.import_module(f"pngail_jax.programs.{program}")
    arguments = rerun_arguments(argv, tmp_path / "out")
    module.build_parser().parse_args(arguments)
    named = [Path(argv[i + 1]) for i, word in enumerate(argv[:-1]) if word in ("--demos", "--conf")]
    if all(path.exists() for path in named):
        module.parse_args(arguments)


def test_an_offline_rerun_cut_short_or_of_an_older_record_is_the_same_run():
    """An offline run writes its trainer's fields when it finishes, so a re-run cut short has
    none: they are compared only where both sides have them; a record from before a setting
    existed (``ilid_union``, ``dwbc_discriminator_updates``) ran with the default of then (the
    union's today's, DWBC's updates every 100th step: ``FORMER_DEFAULTS``), so a re-run of its
    command with the flag that pins it is the same run; a changed setting still differs."""
    from pngail_jax.analysis import run_records
    from pngail_jax.jobs.offline_config import offline_defaults

    record = json.loads((ROOT / "records/offline-pendulum-ilid-intended/record.json").read_text())
    config = copy.deepcopy(record["config"])
    cut = {key: value for key, value in config.items() if key != "trainer"}
    older = copy.deepcopy(record)
    for key in ("ilid_union", "dwbc_discriminator_updates"):
        del older["config"]["config"][key]
    changed = copy.deepcopy(config)
    changed["config"]["ilid_union"] = "released"

    def differences(run, against):
        return run_records.config_differences(run, against, {}, offline_defaults())

    assert differences(cut, record) == []
    assert differences(config, older) == []
    assert differences(cut, older) == []
    assert differences(changed, record) == ["config.ilid_union"]
    today = copy.deepcopy(cut)  # DWBC's updates at today's default, 5,000: another run
    today["config"]["dwbc_discriminator_updates"] = 5000
    assert differences(today, older) == ["config.dwbc_discriminator_updates"]


def test_a_rerun_of_an_offline_record_pins_what_it_ran_with_where_a_default_changed(tmp_path):
    """The re-run of a record whose command named no DWBC updates (every 100th step then, 5,000
    now) adds --dwbc-discriminator-updates every-100, which parses to what the record ran
    with; a record that named a count re-runs its command as it is."""
    from pngail_jax.programs import offline as offline_program
    from pngail_jax.programs import reproduce

    for name, pinned in (("offline-pendulum", True), ("offline-pendulum-dwbc5000", False)):
        record = json.loads((ROOT / f"records/{name}/record.json").read_text())
        program, argv = reproduce.stored_command(record)
        action, arguments = reproduce.plan(record, program, argv, tmp_path / name)
        assert action == "run"
        added = ["--dwbc-discriminator-updates", "every-100"]
        assert (arguments[-2:] == added) is pinned, name
        updates = offline_program.parse_args(arguments).config.dwbc_discriminator_updates
        assert updates == (None if pinned else 5000)
