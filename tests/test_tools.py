"""The developers' tools in tools/: the config walk runs on this checkout and finds no edge
that climbs the layers (the layer test forbids such imports; the walk sees calls through
objects too)."""

import importlib.util
import sys
from pathlib import Path

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
