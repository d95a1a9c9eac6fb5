"""Atomic writes, digest lists and input records: every damage is found and named."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pngail_jax.storage.integrity import (
    MANIFEST_NAME,
    IntegrityError,
    atomic_path,
    atomic_write_text,
    changed_inputs,
    file_record,
    read_json,
    verify_manifest,
    write_json,
    write_manifest,
)


def make_directory(root):
    """A checkpoint-like directory: a nested binary file, an .npz and a JSON file."""
    (root / "state").mkdir(parents=True)
    (root / "state" / "data").write_bytes(np.arange(1000, dtype=np.float32).tobytes())
    np.savez(root / "metrics.npz", loss=np.ones((2, 3)))
    (root / "progress.json").write_text('{"chunks_done": 1}')
    write_manifest(root)
    return root


def test_an_intact_directory_verifies(tmp_path):
    directory = make_directory(tmp_path / "chunk")
    verify_manifest(directory)
    listed = json.loads((directory / MANIFEST_NAME).read_text())["files"]
    assert sorted(listed) == ["metrics.npz", "progress.json", "state/data"]


@pytest.mark.parametrize(
    "damage, expected",
    [
        ("flip one bit", "SHA-256 mismatch"),
        ("overwrite 400 bytes", "SHA-256 mismatch"),
        ("truncate", "bytes where 4,000 were written"),
        ("delete", "missing"),
    ],
)
def test_each_damage_names_the_file(tmp_path, damage, expected):
    directory = make_directory(tmp_path / "chunk")
    target = directory / "state" / "data"
    data = bytearray(target.read_bytes())
    if damage == "flip one bit":
        data[1234] ^= 0x01
    elif damage == "overwrite 400 bytes":
        data[100:500] = bytes(400)
    elif damage == "truncate":
        data = data[: len(data) // 2]
    if damage == "delete":
        target.unlink()
    else:
        target.write_bytes(bytes(data))
    with pytest.raises(IntegrityError, match=expected) as error:
        verify_manifest(directory)
    assert str(target) in str(error.value)


def test_a_directory_without_its_digest_list_is_incomplete(tmp_path):
    directory = make_directory(tmp_path / "chunk")
    (directory / MANIFEST_NAME).unlink()
    with pytest.raises(IntegrityError, match="incomplete"):
        verify_manifest(directory)
    (directory / MANIFEST_NAME).write_text("{not json")
    with pytest.raises(IntegrityError, match=f"{MANIFEST_NAME}: damaged digest list"):
        verify_manifest(directory)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(position=st.integers(0, 4095), bit=st.integers(0, 7))
def test_any_single_bit_flip_is_found(tmp_path_factory, position, bit):
    directory = make_directory(tmp_path_factory.mktemp("chunk") / "c")
    files = sorted(p for p in directory.rglob("*") if p.is_file() and p.name != MANIFEST_NAME)
    sizes = [p.stat().st_size for p in files]
    position %= sum(sizes)
    index = int(np.searchsorted(np.cumsum(sizes), position, side="right"))  # its file
    path, position = files[index], position - sum(sizes[:index])
    data = bytearray(path.read_bytes())
    data[position] ^= 1 << bit
    path.write_bytes(bytes(data))
    with pytest.raises(IntegrityError, match="SHA-256 mismatch"):
        verify_manifest(directory)


def test_atomic_path_leaves_the_old_file_on_failure(tmp_path):
    target = tmp_path / "summary.json"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target) as temporary:
        temporary.write_text("half")
        raise RuntimeError("killed")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["summary.json"]  # no temporary left
    atomic_write_text(target, "new")
    assert target.read_text() == "new"
    with atomic_path(tmp_path / "arrays.npz") as temporary:  # np.savez keeps the name
        np.savez(temporary, x=np.ones(2))
    assert np.load(tmp_path / "arrays.npz")["x"].tolist() == [1.0, 1.0]


def test_json_is_strict_and_its_errors_name_the_file(tmp_path):
    with pytest.raises(ValueError):  # never a bare NaN in a JSON file
        write_json(tmp_path / "a.json", {"x": float("nan")})
    assert not (tmp_path / "a.json").exists()
    (tmp_path / "b.json").write_text('{"x": 1')
    with pytest.raises(IntegrityError, match="b.json: damaged progress record"):
        read_json(tmp_path / "b.json", "progress record")


def test_changed_inputs_name_the_file(tmp_path):
    demos = tmp_path / "demos.npz"
    demos.write_bytes(b"abc")
    records = {"demonstrations": file_record(demos)}
    assert changed_inputs(records) == []
    demos.write_bytes(b"abd")  # same size, other content
    assert changed_inputs(records) == [f"demonstrations {demos} has changed since the run began"]
    demos.unlink()
    assert changed_inputs(records) == [f"demonstrations {demos} is gone"]


def test_a_minari_dataset_is_recorded_by_its_content_not_only_its_id(tmp_path, monkeypatch):
    from pngail_jax.config.run_config import RunConfig
    from pngail_jax.jobs import demonstrations as demos_job
    from pngail_jax.storage.integrity import changed_inputs

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    dataset = tmp_path / "pendulum" / "mine-v0"
    (dataset / "data").mkdir(parents=True)
    (dataset / "data" / "main_data.hdf5").write_bytes(b"episodes")
    (dataset / "metadata.json").write_text("{}")
    config = RunConfig(demos="minari:pendulum/mine-v0")
    records = demos_job.input_files(config, "minari:pendulum/mine-v0")
    assert list(records) == ["Minari dataset"] and records["Minari dataset"]["bytes"] == 10
    assert changed_inputs(records) == []
    (dataset / "data" / "main_data.hdf5").write_bytes(b"episodez")  # rebuilt, same size
    assert changed_inputs(records) == [f"Minari dataset {dataset} has changed since the run began"]
    assert demos_job.input_files(config, "minari:pendulum/other-v0") == {}  # not there: id only
