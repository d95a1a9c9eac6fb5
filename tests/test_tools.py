"""The developers' tools in tools/: the config walk runs on this checkout and finds no edge
that climbs the layers (the layer test forbids such imports; the walk sees calls through
objects too)."""

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tool(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "tools" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_the_config_walk_climbs_no_layer_and_counts_what_it_cannot_follow(capsys):
    out = _tool("config_walk").main([str(ROOT)])
    assert out["climbs_up_layer"] == 0, out["up_layer_edges"]
    assert out["climbs_reentry_on_stack"] == 0, out["on_stack_edges"]
    assert out["stays"] >= out["rooms"] > 10  # it walked the package, not an empty tree
    assert "jobs.sweep (layer jobs)" in out["rooms_list"]
    assert f"{out['stays']} stays in {out['rooms']} rooms" in capsys.readouterr().out


def test_the_objects_walk_is_the_part_of_the_walk_that_receives_config_objects():
    """``--objects`` follows config objects only, so its stays are a subset of the full
    walk's, and it still reaches where the trainers take the config in."""
    tool = _tool("config_walk")
    full, objects = tool.report(ROOT), tool.report(ROOT, objects=True)
    assert set(objects["stays_list"]) < set(full["stays_list"])
    assert "jobs.trainer_configs:adversarial_config" in objects["stays_list"]
    assert "adversarial.trainer:AdversarialTrainer.__init__" in objects["stays_list"]
    assert "envs.base:Env.step" in full["stays_list"]  # a value read from the config, not one
    assert "envs.base:Env.step" not in objects["stays_list"]
    assert objects["climbs_up_layer"] == 0


def test_the_snapshot_drops_wall_clock_columns_and_compare_fails_on_a_result(tmp_path, capsys):
    """A CSV differing only in its wall_seconds column normalises to the same text; two
    manifests that differ in a numeric file make ``compare`` exit 1, equal ones 0."""
    import json

    tool = _tool("behaviour_snapshot")
    context = tool.Context.for_run(tmp_path, tmp_path / "out", None)
    first = b"iteration,method,eval/return,wall_seconds\n1,gail,-150.5,3.2\n"
    later = b"iteration,method,eval/return,wall_seconds\n1,gail,-150.5,9.9\n"
    changed = b"iteration,method,eval/return,wall_seconds\n1,gail,-150.4,3.2\n"
    text, dropped = tool.normalise_csv(first, context)
    assert dropped == ["wall_seconds"] and text == tool.normalise_csv(later, context)[0]
    assert text != tool.normalise_csv(changed, context)[0]

    def manifest(folder, sha):
        folder.mkdir()
        entry = {"kind": "csv", "numeric": True, "sha256": sha}
        document = {"files": {"sweep/metrics.csv": entry}, "commands": [], "skipped": {},
                    "streams (secondary)": {}}  # fmt: skip
        (folder / tool.MANIFEST).write_text(json.dumps(document))
        return str(folder)

    a, b, c = (
        manifest(tmp_path / "a", "1"),
        manifest(tmp_path / "b", "1"),
        manifest(tmp_path / "c", "2"),
    )
    assert tool.main(["compare", a, b]) == 0
    assert tool.main(["compare", a, c]) == 1
    assert "DIFFERENT: 1 difference(s) that count" in capsys.readouterr().out


def test_the_record_trend_ends_with_the_records_headline(capsys):
    """The last of five windows is the last 20% of training: its mean over seeds is the
    record's headline mean for every method."""
    import json

    import numpy as np

    folder = ROOT / "records" / "offline-ant"
    rows = _tool("record_trend").main([str(folder)])
    headline = json.loads((folder / "record.json").read_text())["late_average_normalized_return"]
    assert [row["method"] for row in rows] == list(headline)
    for row in rows:
        assert row["windows"][-1] == pytest.approx(np.mean(headline[row["method"]]), abs=1e-6)
        assert row["change"] == pytest.approx(row["windows"][-1] - row["windows"][-2], abs=1e-9)
    assert "| offline-ant | ILID |" in capsys.readouterr().out


def test_the_contrast_figure_draws_a_panel_per_record_and_refuses_a_broken_one(tmp_path):
    """From two committed comparison records: one panel each, the arms a record lacks left
    out; a record whose numbers do not add up stops it with the check's one line."""
    import json
    import shutil

    tool = _tool("contrast_figure")
    records = [ROOT / "records" / name for name in
               ("settings-swimmer-v4-value-epochs", "settings-hopper-v4-value-epochs")]  # fmt: skip
    out = tool.main([*map(str, records), "--arms", "reference,reference-fast", "--out",
                     str(tmp_path / "figure.png")])  # fmt: skip
    assert out.read_bytes().startswith(b"\x89PNG")
    broken = tmp_path / "broken"
    shutil.copytree(records[0], broken)
    record = json.loads((broken / "record.json").read_text())
    record["comparison"]["arms"]["reference"]["final_return"]["own"][0] += 1.0
    (broken / "record.json").write_text(json.dumps(record))
    with pytest.raises(SystemExit, match="arm reference's final return on the own solver"):
        tool.main([str(broken), "--arms", "reference", "--out", str(tmp_path / "no.png")])
    assert not (tmp_path / "no.png").exists()
