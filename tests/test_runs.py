"""``analysis.runs.read_run_config``, the one reader of a run's config.json: the sweep's flat
layout and the offline program's nested one read into the same view, and no other module
tells the two layouts apart. Small dicts in each layout, as the programs write them."""

import dataclasses
from pathlib import Path

import pytest

from pngail_jax.analysis.run_records import config_differences, planned_iterations
from pngail_jax.analysis.runs import (
    read_run_config,
    recorded_inputs,
    run_document,
    run_progress_numbers,
    run_return_range,
    sealed_part,
)

PACKAGE = Path(__file__).resolve().parents[1] / "pngail_jax"
INPUTS = {"demos": {"path": "d.npy", "sha256": "ab", "bytes": 3}}

SWEEP = {  # experiments.sweep's config.json: the RunConfig flat, then what it resolved
    "env": "Pendulum-v1",
    "methods": ["gail", "pngail"],
    "seeds": 2,
    "label_ratios": [0.2, 0.5],
    "noise_stds": [0.0],
    "iterations": 40,
    "resolved": {
        "inputs": INPUTS,
        "normalizer": [-1500.0, -150.0],
        "normalizer_source": "paper Table 3",
    },
    "provenance": {"git_commit": "abc"},
}
OFFLINE = {  # experiments.offline's: its config nested under "config"
    "program": "offline",
    "config": {
        "env": "Pendulum-v1",
        "methods": ["bc-expert", "dwbc"],
        "seeds": 3,
        "label_ratio": 0.3,
        "noise_std": 0.1,
        "gradient_steps": 2_000,
        "steps_per_iteration": 100,
    },
    "demonstrations": {"rows": 10},
    "input_files": INPUTS,
    "normalizer": [-1500.0, -150.0],
    "normalizer_source": "given",
    "provenance": {"git_commit": "abc"},
    "trainer": {"batch_size": 16},
    "complete": True,
}


def test_a_sweeps_config_reads_as_its_settings_and_what_it_resolved():
    view = read_run_config(SWEEP)
    assert view.program == "sweep" and view.settings is SWEEP
    assert view.settings["env"] == "Pendulum-v1" and view.settings["methods"] == ["gail", "pngail"]
    assert view.sealed == {k: v for k, v in SWEEP.items() if k != "provenance"}
    assert view.inputs == INPUTS and view.return_range == [-1500.0, -150.0]
    assert view.return_range_source == "paper Table 3"
    assert (view.label_ratios, view.noise_stds) == ([0.2, 0.5], [0.0])
    assert view.planned_iterations == 40 and view.complete is None and view.trainer == {}


def test_an_offline_runs_config_reads_as_its_nested_settings():
    view = read_run_config(OFFLINE)
    assert view.program == "offline" and view.settings is OFFLINE["config"]
    assert view.settings["env"] == "Pendulum-v1" and view.settings["seeds"] == 3
    assert set(view.sealed) == {"program", "config", "demonstrations", "input_files",
                                "normalizer", "normalizer_source"}  # fmt: skip
    assert view.inputs == INPUTS and view.return_range == [-1500.0, -150.0]
    assert view.return_range_source == "given"
    assert (view.label_ratios, view.noise_stds) == ([0.3], [0.1])
    assert view.planned_iterations == 20  # 2,000 gradient steps of 100 per iteration
    assert view.complete is True and view.trainer == {"batch_size": 16}


@pytest.mark.parametrize("document", [SWEEP, OFFLINE], ids=["sweep", "offline"])
def test_the_readers_of_one_part_agree_with_the_view(document, tmp_path):
    view = read_run_config(document)
    assert sealed_part(document) == view.sealed
    assert recorded_inputs(document) == view.inputs
    assert run_return_range(document) == view.return_range
    assert planned_iterations(document) == view.planned_iterations
    progress = run_progress_numbers(tmp_path, document)  # no summary.json beside it
    assert progress == ((20, 20) if view.program == "offline" else None)


def test_a_config_missing_parts_reads_as_empty():
    bare = read_run_config({"program": "offline"})
    assert bare.settings == {} and bare.inputs == {} and bare.planned_iterations is None
    assert (bare.return_range, bare.complete) == (None, None)
    unfinished = read_run_config({**OFFLINE, "complete": False})
    assert run_progress_numbers(Path("."), {**OFFLINE, "complete": False}) is None
    assert unfinished.planned_iterations == 20
    sweep = read_run_config({"env": "Pendulum-v1", "iterations": "40"})
    assert sweep.inputs == {} and sweep.return_range is None and sweep.planned_iterations is None


def test_a_train_rl_document_reads_as_its_program():
    """train_rl writes the same layout (its family: reinforcement); its seal covers all but
    the provenance, as every run's."""
    config = {"env": "Pendulum-v1", "iterations": 10, "seeds": 2, "argv": ["--seeds", "2"]}
    document = run_document("train_rl", config, {"rollout": {"num_envs": 4}}, {"python": "3"})
    assert (document["program"], document["family"]) == ("train_rl", "reinforcement")
    view = read_run_config(document)
    assert view.program == "train_rl" and view.settings == config
    assert sealed_part(document) == {k: v for k, v in document.items() if k != "provenance"}
    assert (view.planned_iterations, view.return_range, view.inputs) == (10, None, {})


def test_no_other_module_tells_the_two_layouts_apart():
    """The offline layout is recognised in ``read_run_config`` alone (and in
    ``storage.outputs.output_owner``, below the reading layer, which names the program that
    owns a folder copied without its marker)."""
    marks = ('get("program") == "offline"', 'get("program") in ("offline"')
    found = {
        str(path.relative_to(PACKAGE)): sum(path.read_text().count(mark) for mark in marks)
        for path in PACKAGE.rglob("*.py")
        if any(mark in path.read_text() for mark in marks)
    }
    assert found == {"analysis/runs.py": 1, "storage/outputs.py": 1}


def _today(old: dict) -> dict:
    """``old`` (``SWEEP`` or ``OFFLINE``, of the layouts before ``run_document``) as the
    programs write it today: the same config, resolutions and provenance."""
    if old.get("program") == "offline":
        resolved = {"demos_path": old["demonstrations"], "inputs": old["input_files"],
                    "return_range": old["normalizer"], "trainer": old["trainer"],
                    "return_range_source": old["normalizer_source"]}  # fmt: skip
        document = run_document("offline", old["config"], resolved, old["provenance"])
        return {**document, "complete": old["complete"]}
    config = {key: value for key, value in old.items() if key not in ("resolved", "provenance")}
    resolved = {"inputs": old["resolved"]["inputs"],
                "return_range": old["resolved"]["normalizer"],
                "return_range_source": old["resolved"]["normalizer_source"]}  # fmt: skip
    return run_document("sweep", config, resolved, old["provenance"])


@pytest.mark.parametrize("old", [SWEEP, OFFLINE], ids=["sweep", "offline"])
def test_an_old_layout_and_todays_read_to_the_same_view(old):
    """The upgrade step: a config.json of either layout before ``run_document`` and the
    same run written today read the same (the seal covers each layout's own parts)."""
    new = _today(old)
    assert new["program"] == read_run_config(old).program
    assert new["family"] == {"sweep": "adversarial", "offline": "offline"}[new["program"]]
    old_view, new_view = read_run_config(old), read_run_config(new)
    fields = {key: value for key, value in old_view.settings.items()
              if key not in ("resolved", "provenance")}  # fmt: skip
    assert new_view.settings == fields
    assert dataclasses.replace(old_view, settings={}, sealed={}) == dataclasses.replace(
        new_view, settings={}, sealed={}
    )
    assert new_view.sealed == {key: new[key] for key in ("program", "family", "config", "resolved")}
    assert sealed_part(new) == new_view.sealed and "provenance" not in sealed_part(new)
    assert run_return_range(new) == run_return_range(old) == [-1500.0, -150.0]
    assert planned_iterations(new) == planned_iterations(old)
    # a record of either layout compared with a run of the other: no field differs
    assert config_differences(new, {"config": old}, {}, {}) == []
    assert config_differences(old, {"config": new}, {}, {}) == []
    changed = {**new, "config": {**new["config"], "seeds": 7}}
    assert config_differences(changed, {"config": old}, {}, {}) == [
        "seeds" if old is SWEEP else "config.seeds"
    ]


def test_a_sweeps_config_of_todays_layout_reads_as_the_flat_one_for_its_config():
    """``RunConfig.from_dict`` and a resume read a sweep's config.json of today's layout as
    the flat one: its config's fields with ``resolved`` and ``provenance`` beside them."""
    from pngail_jax.config.saved import sweep_sections, upgrade_saved_config

    new = _today(SWEEP)
    assert sweep_sections(new) == {**new["config"], "resolved": new["resolved"],
                                   "provenance": new["provenance"]}  # fmt: skip
    assert sweep_sections(SWEEP) is SWEEP  # an old layout as it is
    flat = {key: value for key, value in upgrade_saved_config(SWEEP).items() if key != "resolved"}
    today = upgrade_saved_config(new)
    assert {key: value for key, value in today.items() if key != "resolved"} == flat


def test_a_hand_edited_layout_with_a_part_that_is_no_object_reads_as_empty():
    """A config.json whose ``config`` or ``resolved`` was edited into a string reads as an
    empty part (the seal check then names the change in one line), not an AttributeError."""
    from pngail_jax.analysis.runs import read_run_config

    view = read_run_config(
        {"program": "sweep", "family": "adversarial", "config": "x", "resolved": 3}
    )
    assert view.settings == {} and view.inputs == {} and view.return_range is None
