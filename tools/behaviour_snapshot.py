#!/usr/bin/env python3
"""Behaviour snapshot of pngail-jax's command-line programs (issue 57).

A refactor that claims "behaviour unchanged" is checked by running a tiny invocation of every
program before and after, and comparing the outputs byte for byte once the fields that differ
between two identical runs anyway (wall clock, dates, hosts, commits, paths) are taken out.

    git worktree add /tmp/before main          # the commit before the change
    python tools/behaviour_snapshot.py run --repo /tmp/before --out /tmp/snapshot/before
    python tools/behaviour_snapshot.py run --repo .           --out /tmp/snapshot/after
    python tools/behaviour_snapshot.py compare /tmp/snapshot/before /tmp/snapshot/after

``run`` executes every invocation of ``INVOCATIONS`` in order, each as
``python -m experiments.<program> ...`` with cwd=REPO and PYTHONPATH=REPO (so the checkout's
code runs even where an editable install points elsewhere; this is checked once), writing the
program's outputs under OUT/<program>/<name>, with PYTHONHASHSEED=0, MPLBACKEND=Agg and
PNGAIL_JAX_COMPILATION_CACHE=--cache (compiled programs are reused across runs; a cold and a
warm cache gave the same outputs). Programs that read a run (compare, record, seeds,
agreement) read the sweep runs made earlier in the same snapshot. It then writes
OUT/manifest.json: every output file (relative path) -> sha256 of its NORMALISED content, the
commands with exit status and wall time, what was skipped and why, and each command's
normalised stdout/stderr digest (secondary: listed apart, never a failure). The normalised
text of every file is kept under OUT/_normalised/ so that ``compare`` can show what differs.

What is normalised, and why (only fields that are not results; a number a method computes is
never touched):

* Paths: the repository directory, the output directory, the authors' data folder (and the
  real paths behind them), the compilation cache, the temp dir and the home dir become <REPO>,
  <OUT>, <RELEASED>, <CACHE>, <TMP>, <HOME>: two checkouts live in different folders.
  Path-valued fields are kept (with placeholders), not dropped, so that a change of *which*
  file is read still shows.
* JSON (also inside .json.gz): keys whose name holds a token of ``DROP_KEY_TOKENS`` (time,
  seconds, wall, date, started, finished, elapsed, commit, host, machine, version, platform,
  pid, ...) or matches ``DROP_KEY_PATTERNS`` (steps_per_s, *_nsecs, ...) are dropped with
  their whole value; they hold wall-clock readings or describe the machine, the library
  versions or the git commit (which is *meant* to differ between before and after).
  ``KEEP_KEYS`` (format_version, ...) are kept although a token matches.
* CSV (also .csv.gz, decompressed first): columns named as above are dropped (wall_seconds).
* Markdown / text / logs (stdout and stderr also lose their progress lines: speeds, ETAs, the
  "compiling ... 30 s" heartbeat): durations ("1m23s", "12.3 s", "4s", "850 ms"), rates ("23,231 env
  steps/s", "it/s"), ETAs, clock times and dates, and the number after a timing word
  (compile, took, elapsed, throughput, ...) become <DUR>, <RATE>, <TIME>, <DATE>, <N>; a git
  commit after "commit" becomes <COMMIT>; experiments.record's "metrics N bytes" (the size of
  a gzip holding the wall_seconds column) becomes "metrics <N> bytes". Markdown table
  columns whose header names a dropped field ("wall time") become <DROPPED>.
* .npz: each array as name + dtype + shape + raw bytes (the zip container has timestamps).
* Orbax checkpoints (a folder holding an OCDBT manifest.ocdbt: the sweep's chunk states, the
  policies' policy_params): every array read back through tensorstore (orbax's own storage
  layer, installed with it; the one import beyond stdlib + numpy, and optional: without it
  the arrays are listed as skipped) and hashed as name + dtype + shape + bytes: one entry
  <checkpoint>/<arrays>. The files underneath cannot be compared as bytes: orbax packs the
  chunks into data files with random names (ocdbt.process_0/d/<32 hex>, d/<32 hex>) whose
  grouping differs between two writes of the same arrays (4 files one run, 5 the next), and
  manifest.ocdbt points at those names; they are skipped and listed. _CHECKPOINT_METADATA
  and _METADATA are compared as JSON (orbax's init/commit timestamps dropped),
  commit_success.txt as text (its path replaced).
* Digests that a program states of its own outputs: in digests.json and the .*sealed*.json
  seals the per-file sha256/bytes go (the files are compared themselves; random OCDBT names
  become "<random>: present"); record.json's digest of metrics.csv.gz goes (that file holds
  the wall_seconds column; it is compared decompressed, without it), and so does its own
  top-level "digest" (its seal over the whole record, that digest and the commit included).
* A run's list of the files it wrote (.pngail-outputs.json): orbax's random names become
  <random>, each pattern listed once.
* .png: skipped (matplotlib embeds metadata) but listed.
* Anything else: raw bytes.

``digest OUT`` recomputes OUT/manifest.json from the files already there (after a change of the
rules above), running nothing.

``compare A B`` prints every file as same / differ / only in A / only in B and exits 1 if a
numeric output (csv, json, npz, checkpoint arrays) differs or exists on one side only, or a
command's exit status differs; text, markdown and stdout differences are reported only
(``--strict`` makes every difference count).
"""

from __future__ import annotations

import argparse
import csv
import difflib
import gzip
import hashlib
import io
import json
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

MANIFEST = "manifest.json"
NORMALISED = "_normalised"  # OUT/_normalised/<relpath>: the normalised text of each file
LOGS = "_logs"  # OUT/_logs/<name>.stdout|.stderr: each command's raw output
PRIVATE = (MANIFEST, NORMALISED, LOGS)

# --------------------------------------------------------------------------------------------
# The invocations. {OUT} is the snapshot's output folder, {RELEASED} the authors' data folder
# (relative to the repository: data/released). Each writes under {OUT}/<program>/... .
# --------------------------------------------------------------------------------------------

PENDULUM = "{RELEASED}/Pendulum-v1_mixture.npy"
# The paper's seven methods and the appendix baselines (pngail_jax/adversarial/methods.py).
SEVEN = "gail,2iwil,icgail,wgail,pngail,pngail-no-bsc,pngail-no-pn"
APPENDIX_ALL = "pngail,bc,bc-weighted,trex,drex,cail,firl-fkl,firl-rkl,firl-js"
# A tiny adversarial run: 4 envs x 50 steps per iteration, 4 iterations, 50 classifier steps.
TINY_SWEEP = (
    "--iterations 4 --eval-every 1 --chunk-iterations 2 --num-envs 4 --unroll-length 50 "
    "--classifier-steps 50 --cpu-devices 1"
)
TINY_RL = "--iterations 4 --eval-every 2 --seeds 2 --num-envs 4 --unroll-length 50"

# The appendix phases' own sizes (T-REX's 10,000-step reward fit, D-REX's 50,000-step clone and
# 100 noisy rollouts, f-IRL's 1,200 discriminator steps per iteration) are fixed in
# AdversarialConfig and no flag reaches them; at their defaults one T-REX cell takes ~200 s and
# one D-REX cell ~910 s before any RL on a 2-core CPU (pngail_jax/paper/plan.py's own
# measurements). So one sweep of every appendix method runs through this driver, which shrinks
# them (to the sizes of tests/test_appendix_methods.py) and then runs the sweep's own main().
# It patches jobs.trainer_configs.adversarial_config (RunConfig.adversarial_config before
# issue 74's item 1): if the refactor removes that, the driver fails
# (exit status != 0); if the sweep stops calling it, the sizes in config.json's
# resolved.trainer (resolved.adversarial before issue 74's one layout: ranking, drex, bc,
# firl) show the difference. Every other invocation,
# and a second appendix sweep of the cheap phases (bc, cail) at their real sizes, runs the
# programs as they are.
TINY_PHASES_DRIVER = """
import dataclasses, runpy, sys
from pngail_jax.jobs import trainer_configs
from pngail_jax.adversarial import ranking
from pngail_jax.adversarial.bc import BCConfig, DeterministicBCConfig
from pngail_jax.adversarial.firl import FirlConfig
_original = trainer_configs.adversarial_config
def _tiny_phases(*args, **kwargs):
    config = _original(*args, **kwargs)
    return dataclasses.replace(
        config,
        ranking=ranking.RankingConfig(num_steps=20, snippet_length=10, hidden_sizes=(16,)),
        drex=ranking.DrexConfig(
            bc=DeterministicBCConfig(num_steps=20, batch_size=16, hidden_sizes=(16,)),
            noise_levels=(1.0, 0.5, 0.0), rollouts_per_level=1,
            ranking=dataclasses.replace(ranking.DrexConfig().ranking, num_steps=20,
                pairs_per_step=8, num_dataset_pairs=32, hidden_sizes=(16,), num_members=2)),
        bc=BCConfig(num_steps=20, batch_size=16),
        firl=dataclasses.replace(config.firl, discriminator_iterations=5,
                                 discriminator_batch_size=16),
    )
trainer_configs.adversarial_config = _tiny_phases
module = sys.argv[1]
sys.argv = [module, *sys.argv[2:]]
runpy.run_module(module, run_name="__main__", alter_sys=True)
"""


@dataclass(frozen=True)
class Invocation:
    name: str  # OUT/<name> holds its outputs; <program>/<variant>
    program: str  # experiments.<program>
    args: tuple[str, ...]
    driver: str | None = None  # python -c DRIVER experiments.<program> args (else python -m)
    note: str = ""
    # Create OUT/<name> first: the program writes a file there (--json / --out FILE.json) and
    # does not create the folder itself.
    makedirs: bool = False


def _inv(name: str, args: str, **kwargs) -> Invocation:
    """``name`` is <program>/<variant>; ``args`` a shell-like string (shlex-split)."""
    return Invocation(name, name.split("/")[0], tuple(shlex.split(args)), **kwargs)


# fmt: off
INVOCATIONS: tuple[Invocation, ...] = (
    _inv("make_demos/trpo", f"--env Pendulum-v1 --out {{OUT}}/make_demos/trpo {TINY_RL} "
                            "--num-trajectories 5 --measure-episodes 4"),
    _inv("train_rl/trpo", f"--env Pendulum-v1 {TINY_RL} --out {{OUT}}/train_rl/trpo"),
    _inv("train_rl/ppo", f"--env Pendulum-v1 --learner ppo {TINY_RL} --out {{OUT}}/train_rl/ppo"),
    # The paper's seven on the authors' Pendulum file, two label ratios (a grid axis); 4 seeds,
    # the fewest experiments.agreement reads.
    _inv("sweep/seven", f"--demos {PENDULUM} --methods {SEVEN} --label-ratio 0.1,0.2 --seeds 4 "
                        f"{TINY_SWEEP} --out {{OUT}}/sweep/seven"),
    # Confidence noise and a TRPO hyperparameter as grid axes, on the demonstrations made above.
    _inv("sweep/axes", "--demos {OUT}/make_demos/trpo/demos.npz --methods gail,pngail "
                       f"--noise 0,0.1 --grid max_kl=0.005,0.01 --seeds 2 {TINY_SWEEP} "
                       "--out {OUT}/sweep/axes"),
    # Every appendix method (with PN-GAIL) in one grid, its phases shrunk (TINY_PHASES_DRIVER).
    _inv("sweep/appendix-tiny-phases",
         f"--demos {PENDULUM} --methods {APPENDIX_ALL} --seeds 1 {TINY_SWEEP} "
         "--out {OUT}/sweep/appendix-tiny-phases",
         driver=TINY_PHASES_DRIVER, note="appendix phases shrunk by TINY_PHASES_DRIVER"),
    # The cheap appendix phases (bc: 2,000 steps; cail) at their real sizes, the CLI untouched.
    _inv("sweep/appendix-bc-cail", f"--demos {PENDULUM} --methods bc,bc-weighted,cail --seeds 2 "
                                   f"{TINY_SWEEP} --out {{OUT}}/sweep/appendix-bc-cail"),
    _inv("sweep/ppo", f"--demos {PENDULUM} --methods gail,pngail,bc,cail --learner ppo --seeds 2 "
                      f"{TINY_SWEEP} --out {{OUT}}/sweep/ppo"),
    _inv("classify/released", f"--demos {PENDULUM} --seeds 2 --classifier-steps 50 "
                              "--json {OUT}/classify/released/classify.json", makedirs=True),
    _inv("compare_settings/pendulum", "--env Pendulum-v1 --arms table,table-normalized --seeds 2 "
                                      "--iterations 2 --eval-every 1 --num-eval-episodes 2 "
                                      "--out {OUT}/compare_settings/pendulum"),
    _inv("early_rewards/released", f"--demos {PENDULUM} --seeds 1 --iterations 2 --every 1 "
                                   "--classifier-steps 10 "
                                   "--out {OUT}/early_rewards/released/early_rewards.json",
         makedirs=True),
    _inv("offline/released", f"--demos {PENDULUM} --methods bc-expert,bc-all,dwbc,iswbc,ilid "
                             "--seeds 2 --gradient-steps 40 --steps-per-iteration 10 "
                             "--eval-every 2 --chunk-iterations 2 --batch-size 8 "
                             "--ilid-discriminator-steps 5 --out {OUT}/offline/released"),
    # The paper's plan at its test preset: made demonstrations, the main grid, three figures;
    # then its page written again from the finished plan.
    _inv("paper/test", "--preset test --only fig2,fig3,table1 --envs Pendulum-v1 "
                       "--out {OUT}/paper/test"),
    _inv("paper/page", "--page {OUT}/paper/test --out {OUT}/paper/page"),
    # Programs that read the runs above (and the repository's kept record).
    _inv("seeds/seven", "{OUT}/sweep/seven --method pngail --setting label_ratio=0.2,noise=0 "
                        "--share 0.5 --json {OUT}/seeds/seven/seeds.json", makedirs=True),
    _inv("compare/seven", "{OUT}/sweep/seven --expected records/pendulum-1000-5seeds "
                          "--out {OUT}/compare/seven"),
    _inv("compare/runs", "{OUT}/sweep/appendix-tiny-phases {OUT}/sweep/appendix-bc-cail "
                         "--statistic final --out {OUT}/compare/runs"),
    _inv("record/seven", "{OUT}/sweep/seven --name seven --records {OUT}/record/seven"),
    _inv("record/check", "--check {OUT}/record/seven/seven"),
    _inv("agreement/seven", "{OUT}/sweep/seven --lasts 1,2 --splits 200 "
                            "--json {OUT}/agreement/seven/agreement.json", makedirs=True),
    _inv("agreement/record", "records/pendulum-1000-5seeds --lasts 1,3 --splits 200 "
                             "--json {OUT}/agreement/record/agreement.json", makedirs=True),
)
# fmt: on

# --------------------------------------------------------------------------------------------
# Normalisation
# --------------------------------------------------------------------------------------------

# A JSON key or CSV column is dropped when one of its tokens (split at _ - . / space and at
# lowercase-uppercase boundaries) is one of these ...
DROP_KEY_TOKENS = frozenset(
    """
    time times timing timings timestamp timestamps clock wall seconds second secs sec nsecs
    ms elapsed duration durations eta date dates datetime started finished start_time
    commit commits git host hostname hostnames machine node uname version versions platform
    pid pids user cwd
""".split()
)
# ... or it matches one of these (searched in the lower-cased key).
DROP_KEY_PATTERNS = tuple(re.compile(p) for p in (
    r"steps_per_s", r"per_second", r"per_s$", r"/s$", r"throughput", r"_at$",
    r"^command_line$", r"^cpu_model$", r"^xla_flags$", r"^libraries$",
))  # fmt: skip
# Kept although a token matches: not a reading of the clock or the machine.
KEEP_KEYS = frozenset({"format_version", "format"})
# Files whose JSON holds digests of their siblings' raw bytes (see the docstring).
DIGEST_FILES = re.compile(r"(^|/)(digests\.json|\.[^/]*seal[^/]*\.json)$")
# Digests of these files, wherever a JSON states one ({"file": ..., "bytes": ..., "sha256": ...},
# experiments.record's record.json), are dropped: their raw bytes hold the wall_seconds column;
# the files themselves are compared with that column dropped.
DIGESTED_OUTPUT = re.compile(r"(^|/)metrics\.csv(\.gz)?$")
# Orbax/OCDBT files that name random files or hold nothing but pointers.
RANDOM_NAME = re.compile(r"^[0-9a-f]{32}$")
# A run's list of the files it wrote ({"program": ..., "files": [...]}): orbax's random names
# in it become <random>, listed once (how many there are differs between two writes).
OUTPUT_LIST = re.compile(r"(^|/)\.pngail-outputs\.json$")
# experiments.record's record.json: its top-level "digest" seals the record, whose metrics
# digest covers the wall_seconds column and whose commit and machine fields differ by design.
RECORD = re.compile(r"(^|/)record\.json$")


def _tokens(key: str) -> list[str]:
    key = re.sub(r"([a-z0-9])([A-Z])", r"\1_\2", key)
    return [t for t in re.split(r"[^0-9A-Za-z]+", key.lower()) if t]


def drop_key(key: str) -> bool:
    if key in KEEP_KEYS:
        return False
    lowered = key.lower()
    return bool(set(_tokens(key)) & DROP_KEY_TOKENS) or any(
        p.search(lowered) for p in DROP_KEY_PATTERNS
    )


_NUM = r"\d[\d,]*(?:\.\d+)?(?:[eE][-+]?\d+)?"
TEXT_RULES: tuple[tuple[re.Pattern, str], ...] = tuple(
    (re.compile(p), r) for p, r in (
        # ISO timestamps and dates, clock times, run-folder stamps (20240101-120000)
        (r"\d{4}-\d\d-\d\d[T ]\d\d:\d\d(?::\d\d(?:\.\d+)?)?(?:Z|[+-]\d\d:?\d\d)?", "<TIMESTAMP>"),
        (r"\b\d{8}[-_T]\d{6}\b", "<TIMESTAMP>"),
        (r"\b\d{4}-\d\d-\d\d\b", "<DATE>"),
        (r"\b\d{1,2}:\d\d:\d\d(?:\.\d+)?\b", "<TIME>"),  # h:mm:ss, not a ratio like 1:10
        # rates: "23,231 env steps/s", "1.2 it/s", "9,000 gradient steps/s", "12 steps/sec"
        (rf"{_NUM}\s*(?:[A-Za-z_-]+\s+){{0,3}}?[A-Za-z_-]*/\s?(?:s|sec|second)\b", "<RATE>"),
        (rf"{_NUM}\s*(?:[A-Za-z_-]+\s+){{0,3}}?(?:per|a)\s+second\b", "<RATE>"),
        # durations: 1h02m, 1m23s, 1m23.4s, 12.3 s, 4s, 850 ms, 3 min, 2 minutes, 1.5 hours
        (r"\b\d+h\s?\d+m(?:\s?\d+(?:\.\d+)?s)?\b", "<DUR>"),
        (r"\b\d+m\s?\d+(?:\.\d+)?s\b", "<DUR>"),
        (rf"(?<![\w.]){_NUM}\s*(?:ms|s|sec|secs|seconds?|min|mins|minutes?|h|hrs?|hours?)\b(?!\.e\.)",
         "<DUR>"),
        # the number after a timing word: "compile 9.8", "took 3", "ETA 0:12", "elapsed: 5"
        (rf"(?i)\b(compile[ds]?|compiling|compilation|took|elapsed|wall(?:[- ]clock)?|eta|"
         rf"throughput|runtime|run time|time)(\s*[:=]?\s*)(?:~\s*)?{_NUM}", r"\1\2<N>"),
        (r"(?i)\bpid\s*[:=]?\s*\d+", "pid <N>"),
        # a git commit, and experiments.record's size of its metrics.csv.gz (which holds the
        # wall_seconds column)
        (r"(?i)\b(commit|HEAD|revision)(\s*[:=]?\s*)[0-9a-f]{7,40}\b", r"\1\2<COMMIT>"),
        (r"\bmetrics [\d,]+ bytes\b", "metrics <N> bytes"),
    )
)  # fmt: skip


@dataclass
class Context:
    """What paths become which placeholder (longest first)."""

    replacements: list[tuple[str, str]] = field(default_factory=list)

    @classmethod
    def for_run(
        cls, repo: Path, out: Path, cache: Path | None, ran_in: Path | None = None
    ) -> Context:
        """``ran_in``: where the snapshot was written, if it has moved since (``digest``)."""
        pairs = {}
        for path, label in ((out, "<OUT>"), (ran_in or out, "<OUT>"), (repo, "<REPO>")):
            pairs[str(path)] = label
            pairs[os.path.realpath(path)] = label
        released = repo / "data" / "released"
        if released.exists():
            pairs[os.path.realpath(released)] = "<RELEASED>"
        if cache is not None:
            pairs[str(cache)] = "<CACHE>"
            pairs[os.path.realpath(cache)] = "<CACHE>"
        pairs[tempfile.gettempdir() + "/"] = "<TMP>/"
        pairs[str(Path.home()) + "/"] = "<HOME>/"
        ordered = sorted(pairs.items(), key=lambda item: -len(item[0]))
        return cls([(k, v) for k, v in ordered if k and k != "/"])

    def paths(self, text: str) -> str:
        for path, label in self.replacements:
            text = text.replace(path, label)
        return text

    def text(self, text: str) -> str:
        text = _markdown_tables(self.paths(text))
        for pattern, replacement in TEXT_RULES:
            text = pattern.sub(replacement, text)
        return text

    def json_value(self, value, digest_file: bool = False):
        if isinstance(value, dict):
            result = {}
            for key, item in value.items():
                file_name = digest_file and ("/" in str(key) or "." in str(key))
                if drop_key(str(key)) and not file_name:
                    continue
                if digest_file and str(key) in ("sha256", "bytes", "digest", "size"):
                    continue
                result[self.paths(str(key))] = self.json_value(item, digest_file)
            if DIGESTED_OUTPUT.search(str(value.get("file", ""))):
                result.pop("sha256", None), result.pop("bytes", None)
            if digest_file:  # random OCDBT names: keep that there are some, not which
                result = _collapse_random_names(result)
            return result
        if isinstance(value, list):
            return [self.json_value(item, digest_file) for item in value]
        if isinstance(value, str):
            return self.paths(value)
        return value


def _markdown_tables(text: str) -> str:
    """Markdown table columns whose header names a dropped field ("wall time", "seconds"):
    their cells become <DROPPED>."""
    lines = text.split("\n")
    drop: list[int] = []
    for index, line in enumerate(lines):
        if not line.lstrip().startswith("|"):
            drop = []
            continue
        cells = line.split("|")
        following = lines[index + 1] if index + 1 < len(lines) else ""
        if not drop and re.fullmatch(r"\s*\|(\s*:?-+:?\s*\|)+\s*", following):
            drop = [i for i, cell in enumerate(cells) if cell.strip() and drop_key(cell.strip())]
            continue  # the header row itself is kept
        if re.fullmatch(r"\s*\|(\s*:?-+:?\s*\|)+\s*", line):
            continue
        for i in drop:
            if i < len(cells) - 1:
                cells[i] = " <DROPPED> "
        lines[index] = "|".join(cells)
    return "\n".join(lines)


def _random_names_out(paths: list) -> list:
    """A list of relative paths with each random OCDBT name as <random>, each path once."""
    found = []
    for path in paths:
        parts = str(path).split("/")
        pattern = "/".join("<random>" if RANDOM_NAME.match(part) else part for part in parts)
        if pattern not in found:
            found.append(pattern)
    return found


def _collapse_random_names(mapping: dict) -> dict:
    kept, random = {}, {}
    for key, value in mapping.items():
        if any(RANDOM_NAME.match(part) for part in key.split("/")):
            pattern = "/".join("<random>" if RANDOM_NAME.match(p) else p for p in key.split("/"))
            random[pattern] = random.get(pattern, 0) + 1
        else:
            kept[key] = value
    for pattern in random:  # how many there are differs between two writes of the same arrays
        kept[pattern] = "present"
    return kept


def _sha(data: bytes | str) -> str:
    if isinstance(data, str):
        data = data.encode()
    return hashlib.sha256(data).hexdigest()


def _numbers_out(value):
    if isinstance(value, dict):
        return {k: _numbers_out(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_numbers_out(v) for v in value]
    return "<N>" if isinstance(value, int | float) and not isinstance(value, bool) else value


def normalise_json(raw: bytes, ctx: Context, relpath: str) -> str:
    document = json.loads(raw)
    digest_file = bool(DIGEST_FILES.search(relpath))
    value = ctx.json_value(document, digest_file)
    if OUTPUT_LIST.search(relpath) and isinstance(value, dict):
        value = {**value, "files": _random_names_out(value.get("files", []))}
    if RECORD.search(relpath) and isinstance(value, dict):
        value.pop("digest", None)  # the record's seal: over metrics' bytes, commit, machine
    if drop_key(Path(relpath).name.split(".")[0]):  # a file of timings (paper's timings.json)
        value = _numbers_out(value)
    return json.dumps(value, indent=1, sort_keys=False) + "\n"


def normalise_csv(raw: bytes, ctx: Context) -> tuple[str, list[str]]:
    rows = list(csv.reader(io.StringIO(raw.decode())))
    if not rows:
        return "", []
    keep = [i for i, name in enumerate(rows[0]) if not drop_key(name)]
    dropped = [name for i, name in enumerate(rows[0]) if i not in keep]
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    for row in rows:
        writer.writerow([ctx.paths(row[i]) if i < len(row) else "" for i in keep])
    return out.getvalue(), dropped


def normalise_npz(raw: bytes) -> str:
    lines = []
    with np.load(io.BytesIO(raw), allow_pickle=False) as archive:
        for name in sorted(archive.files):
            array = np.ascontiguousarray(archive[name])
            lines.append(f"{name} {array.dtype.str} {list(array.shape)} {_sha(array.tobytes())}")
    return "\n".join(lines) + "\n"


TEXT_SUFFIXES = {".md", ".txt", ".log", ".csv", ".json", ".tex", ".html", ".yaml", ".yml"}


@dataclass
class Entry:
    kind: str  # json | csv | npz | checkpoint-arrays | text | binary
    sha256: str
    numeric: bool
    note: str = ""


def classify_and_normalise(path: Path, relpath: str, ctx: Context) -> tuple[Entry, str | None]:
    """The entry of one file and its normalised text (None for raw bytes)."""
    raw = path.read_bytes()
    name = path.name
    inner = name
    if name.endswith(".gz"):
        raw = gzip.decompress(raw)
        inner = name[:-3]
    suffix = Path(inner).suffix.lower()
    if name in ("_CHECKPOINT_METADATA", "_METADATA") or suffix == ".json":
        try:
            text = normalise_json(raw, ctx, relpath)
            return Entry("json", _sha(text), True), text
        except (ValueError, UnicodeDecodeError):
            pass
    if suffix == ".csv":
        text, dropped = normalise_csv(raw, ctx)
        note = f"dropped columns {dropped}" if dropped else ""
        return Entry("csv", _sha(text), True, note), text
    if suffix == ".npz":
        try:
            text = normalise_npz(raw)
            return Entry("npz", _sha(text), True), text
        except (ValueError, OSError, zipfile.BadZipFile) as error:
            return Entry("binary", _sha(raw), True, f"npz unreadable: {error}"), None
    if suffix == ".npy":
        array = np.load(io.BytesIO(raw), allow_pickle=False)
        text = (
            f"{array.dtype.str} {list(array.shape)} {_sha(np.ascontiguousarray(array).tobytes())}\n"
        )
        return Entry("npz", _sha(text), True), text
    if suffix in TEXT_SUFFIXES or name == "commit_success.txt" or suffix == "":
        try:
            text = ctx.text(raw.decode())
            return Entry("text", _sha(text), False), text
        except UnicodeDecodeError:
            pass
    return Entry("binary", _sha(raw), False), None


def is_ocdbt_checkpoint(folder: Path) -> bool:
    """An orbax checkpoint item stored as an OCDBT database (its root manifest.ocdbt)."""
    return (folder / "manifest.ocdbt").is_file()


def checkpoint_arrays(folder: Path) -> str | None:
    """Every array of an OCDBT checkpoint as 'name dtype shape sha256' lines, read through
    tensorstore (orbax's own storage layer, installed with it), or None without tensorstore.
    Orbax packs the arrays' chunks into data files whose names are random and whose grouping
    differs from one write to the next, so the files' bytes cannot be compared; the arrays
    can."""
    try:
        import tensorstore as ts
    except ImportError:
        return None
    base = {"driver": "ocdbt", "base": f"file://{folder.resolve()}/"}
    lines = []
    for key in sorted(k.decode() for k in ts.KvStore.open(base).result().list().result()):
        for marker, driver in (("/.zarray", "zarr"), ("/zarr.json", "zarr3")):
            if key.endswith(marker):
                name = key[: -len(marker)]
                spec = {"driver": driver, "kvstore": {**base, "path": name + "/"}}
                array = np.ascontiguousarray(ts.open(spec, open=True).result().read().result())
                lines.append(f"{name} {array.dtype.str} {list(array.shape)} "
                             f"{_sha(array.tobytes())}")  # fmt: skip
    return "\n".join(lines) + "\n"


def _folders_up_to(folder: Path, root: Path):
    while folder != root and root in folder.parents:
        yield folder
        folder = folder.parent


def _write_normalised(out: Path, relpath: str, text: str) -> None:
    target = out / NORMALISED / relpath
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(text)


def digest_tree(out: Path, ctx: Context) -> tuple[dict, dict]:
    """(files, skipped) of everything under ``out`` but the snapshot's own files."""
    files: dict[str, dict] = {}
    skipped: dict[str, str] = {}
    for dirpath, dirnames, filenames in os.walk(out):
        folder = Path(dirpath)
        rel_folder = folder.relative_to(out).as_posix()
        if rel_folder == ".":
            dirnames[:] = [d for d in dirnames if d not in PRIVATE]
            filenames = [f for f in filenames if f not in PRIVATE]
        dirnames.sort()
        in_checkpoint = any(is_ocdbt_checkpoint(p) for p in _folders_up_to(folder, out))
        if is_ocdbt_checkpoint(folder):
            relpath = f"{rel_folder}/<arrays>"
            text = checkpoint_arrays(folder)
            if text is None:
                skipped[relpath] = "checkpoint arrays: tensorstore is not importable"
            else:
                files[relpath] = Entry("checkpoint-arrays", _sha(text), True).__dict__
                _write_normalised(out, f"{rel_folder}/arrays.txt", text)
        random_files = 0
        for filename in sorted(filenames):
            path = folder / filename
            relpath = path.relative_to(out).as_posix()
            if path.is_symlink():
                skipped[relpath] = "a link"
            elif filename.lower().endswith(".png"):
                skipped[relpath] = "png (matplotlib embeds metadata)"
            elif in_checkpoint and RANDOM_NAME.match(filename):
                random_files += 1
            elif in_checkpoint and filename == "manifest.ocdbt":
                skipped[relpath] = "OCDBT manifest (points at random file names)"
            else:
                entry, text = classify_and_normalise(path, relpath, ctx)
                files[relpath] = entry.__dict__
                if text is not None:
                    _write_normalised(out, relpath, text)
        if random_files:
            skipped[f"{rel_folder}/<random-named files>"] = (
                "OCDBT data / b-tree files (random names, grouping differs between writes; "
                "the arrays are compared as <arrays>)"
            )
    return files, skipped


# --------------------------------------------------------------------------------------------
# run
# --------------------------------------------------------------------------------------------


def _command(invocation: Invocation, out: Path, python: str) -> list[str]:
    args = [a.replace("{OUT}", str(out)).replace("{RELEASED}", "data/released")
            for a in invocation.args]  # fmt: skip
    module = f"experiments.{invocation.program}"
    if invocation.driver:
        return [python, "-c", invocation.driver, module, *args]
    return [python, "-m", module, *args]


def _shown(command: list[str]) -> str:
    """The command as one line, the driver's code named rather than printed."""
    parts = []
    for index, part in enumerate(command):
        if index > 0 and command[index - 1] == "-c":
            parts.append("<TINY_PHASES_DRIVER>")
        elif re.search(r"[^\w@%+=:,./-]", part):
            parts.append("'" + part.replace("'", "'\\''") + "'")
        else:
            parts.append(part)
    return " ".join(parts)


def run(args) -> int:
    """Runs the selected invocations on ``--repo`` into ``--out`` and writes the manifest."""
    repo = Path(args.repo).resolve()
    out = Path(args.out).resolve()
    cache = Path(args.cache).resolve() if args.cache else None
    python = args.python or sys.executable
    env, imported = _prepare_run(repo, out, cache, python, args.overwrite)
    before_status = _git_status(repo)
    selected = [
        i
        for i in INVOCATIONS
        if not args.only or any(i.name.startswith(o) for o in args.only.split(","))
    ]
    started = time.monotonic()
    commands = [_run_one(invocation, repo, out, env, python, started) for invocation in selected]
    meta = {
        "repo": str(repo),
        "out": str(out),
        "git_head": _git(repo, "rev-parse", "HEAD"),
        "pngail_jax_imported_from": imported,
        "python": python,
        "compilation_cache": str(cache) if cache else None,
        "total_wall_seconds": round(time.monotonic() - started, 1),
        "commands": commands,
        "created_in_repo": sorted(set(_git_status(repo)) - set(before_status)),
    }
    write_manifest(out, meta)
    failed = [c["name"] for c in commands if c["exit_status"]]
    print(
        f"\n{len(commands)} commands in {meta['total_wall_seconds']:.0f}s; failed: "
        f"{failed or 'none'}"
    )
    if meta["created_in_repo"]:
        print(f"WARNING: new or changed files in {repo}: {meta['created_in_repo']}")
    return 1 if failed else 0


def _prepare_run(repo: Path, out: Path, cache, python: str, overwrite: bool):
    """An empty ``out`` and the programs' environment; checks that ``repo``'s code is what
    imports. Returns (environment, where pngail_jax imports from)."""
    if out.exists() and any(out.iterdir()):
        if not overwrite:
            sys.exit(f"{out} is not empty (--overwrite to empty it)")
        import shutil

        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / LOGS).mkdir()
    env = {**os.environ, "PYTHONPATH": str(repo), "PYTHONHASHSEED": "0", "MPLBACKEND": "Agg"}
    if cache is not None:
        env["PNGAIL_JAX_COMPILATION_CACHE"] = str(cache)
    where = subprocess.run(
        [python, "-c", "import pngail_jax; print(pngail_jax.__file__)"],
        cwd=repo, env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    imported = where.stdout.strip()
    if where.returncode or not Path(imported).resolve().is_relative_to(repo):
        sys.exit(f"pngail_jax imports from {imported or where.stderr.strip()}, not from {repo}")
    print(f"pngail_jax from {imported}")
    return env, imported


def _run_one(invocation, repo: Path, out: Path, env: dict, python: str, started: float) -> dict:
    """Runs one invocation, its stdout and stderr logged under OUT/LOGS: its manifest row."""
    command = _command(invocation, out, python)
    print(f"[{time.monotonic() - started:6.0f}s] {invocation.name}: {_shown(command)}", flush=True)
    t0 = time.monotonic()
    log = out / LOGS / invocation.name.replace("/", "__")
    if invocation.makedirs:
        (out / invocation.name).mkdir(parents=True, exist_ok=True)
    with open(f"{log}.stdout", "wb") as stdout, open(f"{log}.stderr", "wb") as stderr:
        done = subprocess.run(command, cwd=repo, env=env, stdout=stdout, stderr=stderr,
                              check=False)  # fmt: skip
    wall = time.monotonic() - t0
    print(f"         exit {done.returncode} in {wall:.1f}s", flush=True)
    if done.returncode:
        print("         " + Path(f"{log}.stderr").read_text()[-2000:].replace("\n", "\n         "))
    return {
        "name": invocation.name, "program": invocation.program, "note": invocation.note,
        "command": _shown(command).replace(str(out), "<OUT>").replace(python, "python"),
        "exit_status": done.returncode, "wall_seconds": round(wall, 1),
    }  # fmt: skip


def write_manifest(out: Path, meta: dict) -> None:
    """Digests everything under ``out`` (normalised copies into OUT/_normalised) and writes
    OUT/manifest.json: ``meta`` (the run's commands, ...) and the digests."""
    import shutil

    shutil.rmtree(out / NORMALISED, ignore_errors=True)
    cache = Path(meta["compilation_cache"]) if meta.get("compilation_cache") else None
    ran_in = Path(meta["out"]) if meta.get("out") else None
    ctx = Context.for_run(Path(meta["repo"]), out, cache, ran_in)
    files, skipped = digest_tree(out, ctx)
    streams = {}
    for command in meta["commands"]:
        log = out / LOGS / command["name"].replace("/", "__")
        for stream in ("stdout", "stderr"):
            text = ctx.text(_drop_progress(Path(f"{log}.{stream}").read_text(errors="replace")))
            target = out / NORMALISED / LOGS / f"{log.name}.{stream}"
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(text)
            streams[f"{command['name']} {stream}"] = _sha(text)
    manifest = {
        **meta,
        "files": dict(sorted(files.items())),
        "skipped": dict(sorted(skipped.items())),
        "streams (secondary)": streams,
        "normalisation": {
            "drop_key_tokens": sorted(DROP_KEY_TOKENS),
            "drop_key_patterns": [p.pattern for p in DROP_KEY_PATTERNS],
            "keep_keys": sorted(KEEP_KEYS),
            "text_rules": [[p.pattern, r] for p, r in TEXT_RULES],
            "placeholders": [[k, v] for k, v in ctx.replacements],
        },
    }
    (out / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
    print(f"{len(files)} files digested, {len(skipped)} skipped; manifest: {out / MANIFEST}")


def digest(args) -> int:
    """Re-normalises an existing snapshot (after the rules changed), running nothing."""
    out = Path(args.out).resolve()
    manifest = json.loads((out / MANIFEST).read_text())
    keys = ("repo", "out", "git_head", "pngail_jax_imported_from", "python", "compilation_cache",
            "total_wall_seconds", "commands", "created_in_repo")  # fmt: skip
    write_manifest(out, {key: manifest.get(key) for key in keys})
    return 0


# Progress lines: a speed, an ETA or a carriage return, and pngail_jax.analysis.tracking.ticking's
# heartbeat ("compiling ... 30 s", a line every 30 s of a slow step: how many depends on speed).
PROGRESS = re.compile(r"(?i)(\bETA\b|it/s|steps/s|\r)|^.* \.\.\. \d+ s$")


def _drop_progress(text: str) -> str:
    """Progress lines go; the rest is normalised like any text."""
    return "".join(
        line for line in text.splitlines(keepends=True) if not PROGRESS.search(line.rstrip("\n"))
    )


def _git(repo: Path, *args: str) -> str | None:
    done = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True,
                          check=False)  # fmt: skip
    return done.stdout.strip() if done.returncode == 0 else None


def _git_status(repo: Path) -> list[str]:
    status = _git(repo, "status", "--porcelain", "--untracked-files=all")
    return status.splitlines() if status else []


# --------------------------------------------------------------------------------------------
# compare
# --------------------------------------------------------------------------------------------


def compare(args) -> int:
    """Compares two snapshots' manifests; 1 when a difference that counts is found."""
    a_dir, b_dir = Path(args.a), Path(args.b)
    a = json.loads((a_dir / MANIFEST).read_text())
    b = json.loads((b_dir / MANIFEST).read_text())
    rows = _file_rows(a, b, args.strict)
    failures = sum(counts for *_, counts in rows)
    _print_file_rows(a_dir, b_dir, a, b, rows, args.all)
    failures += _compare_commands(a, b)
    differing = _compare_skipped_and_streams(a, b)
    if args.diff:
        for status, _kind, name, _counts in rows:
            if status == "differ":
                _show_diff(a_dir, b_dir, name, args.diff)
        for key in differing:
            cmd, stream = key.rsplit(" ", 1)
            rel = f"{LOGS}/{cmd.replace('/', '__')}.{stream}"
            _show_diff(a_dir, b_dir, rel, args.diff)
    print(f"\n{'DIFFERENT' if failures else 'SAME'}: {failures} difference(s) that count")
    return 1 if failures else 0


def _file_rows(a: dict, b: dict, strict: bool) -> list[tuple]:
    """(status, kind, file, counts) of every file in either manifest."""
    rows = []
    for name in sorted(set(a["files"]) | set(b["files"])):
        ea, eb = a["files"].get(name), b["files"].get(name)
        numeric = (ea or eb)["numeric"]
        kind = (ea or eb)["kind"]
        if ea is None:
            status = "only in B"
        elif eb is None:
            status = "only in A"
        else:
            status = "same" if ea["sha256"] == eb["sha256"] else "differ"
        counts = status != "same" and (numeric or strict)
        rows.append((status, kind, name, counts))
    return rows


def _print_file_rows(a_dir, b_dir, a: dict, b: dict, rows: list[tuple], show_all: bool) -> None:
    width = max((len(r[2]) for r in rows), default=10)
    shown = rows if show_all else [r for r in rows if r[0] != "same"]
    summary: dict[str, int] = {}
    for status, *_ in rows:
        summary[status] = summary.get(status, 0) + 1
    print(f"A = {a_dir} ({a.get('git_head')}), B = {b_dir} ({b.get('git_head')})\n")
    print(f"{'status':10} {'kind':17} {'file':{width}}  counts")
    for status, kind, name, counts in shown:
        print(f"{status:10} {kind:17} {name:{width}}  {'FAIL' if counts else ''}")
    if not show_all:
        print(f"(... and {summary.get('same', 0)} files the same; --all lists them)")
    print("\nfiles: " + ", ".join(f"{v} {k}" for k, v in sorted(summary.items())))


def _compare_commands(a: dict, b: dict) -> int:
    """Commands whose exit status differs (each counts)."""
    failures = 0
    status_a = {c["name"]: c["exit_status"] for c in a["commands"]}
    status_b = {c["name"]: c["exit_status"] for c in b["commands"]}
    for name in sorted(set(status_a) | set(status_b)):
        if status_a.get(name) != status_b.get(name):
            failures += 1
            print(
                f"command {name}: exit {status_a.get(name)} in A, {status_b.get(name)} in B  FAIL"
            )
    return failures


def _compare_skipped_and_streams(a: dict, b: dict) -> list[str]:
    """Prints the skipped files present on one side and the differing stdout / stderr
    streams (never failures); returns those streams."""
    # Skipped files (png, OCDBT pointers): listed, only their presence compared.
    skipped_a, skipped_b = set(a["skipped"]), set(b["skipped"])
    print(
        f"skipped (not compared): {len(skipped_a)} in A, {len(skipped_b)} in B; "
        f"present in one only: {_some(sorted(skipped_a ^ skipped_b))}"
    )
    # Stdout / stderr: secondary.
    streams_a, streams_b = a["streams (secondary)"], b["streams (secondary)"]
    differing = [k for k in sorted(set(streams_a) | set(streams_b))
                 if streams_a.get(k) != streams_b.get(k)]  # fmt: skip
    print(
        f"stdout/stderr (secondary, never a failure): {len(streams_a)} streams, "
        f"differ: {_some(differing)}"
    )
    return differing


def _some(names: list[str], shown: int = 10) -> str:
    if not names:
        return "none"
    more = f" ... and {len(names) - shown} more" if len(names) > shown else ""
    return ", ".join(names[:shown]) + more


def _show_diff(a_dir: Path, b_dir: Path, rel: str, lines: int) -> None:
    if rel.endswith("<arrays>"):
        rel = rel.replace("<arrays>", "arrays.txt")
    pa, pb = a_dir / NORMALISED / rel, b_dir / NORMALISED / rel
    if not (pa.exists() and pb.exists()):
        print(f"\n--- {rel}: raw bytes differ (no normalised text)")
        return
    diff = list(difflib.unified_diff(pa.read_text().splitlines(), pb.read_text().splitlines(),
                                     f"A/{rel}", f"B/{rel}", n=1, lineterm=""))  # fmt: skip
    print(
        "\n"
        + "\n".join(diff[:lines])
        + (f"\n... ({len(diff) - lines} more lines)" if len(diff) > lines else "")
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="mode", required=True)
    r = sub.add_parser("run", help="run every tiny invocation and write OUT/manifest.json")
    r.add_argument("--repo", required=True, help="the checkout to run (cwd and PYTHONPATH)")
    r.add_argument("--out", required=True, help="output folder (must be empty or new)")
    r.add_argument("--cache", default=str(Path.home() / ".cache" / "pngail-jax" / "snapshot-xla"),
                   help="PNGAIL_JAX_COMPILATION_CACHE (default: ~/.cache/pngail-jax/snapshot-xla, "
                        "outside every checkout; '' for the programs' default)")  # fmt: skip
    r.add_argument("--python", help="interpreter (default: this one)")
    r.add_argument("--only", help="comma-separated name prefixes of INVOCATIONS to run")
    r.add_argument("--overwrite", action="store_true", help="empty a non-empty --out first")
    d = sub.add_parser("digest", help="re-digest an existing snapshot, running nothing")
    d.add_argument("out")
    c = sub.add_parser("compare", help="compare two snapshots' manifests")
    c.add_argument("a")
    c.add_argument("b")
    c.add_argument("--all", action="store_true", help="list the files that are the same too")
    c.add_argument("--strict", action="store_true", help="every difference counts")
    c.add_argument("--diff", type=int, default=0, metavar="LINES",
                   help="show up to LINES lines of each normalised diff")  # fmt: skip
    args = parser.parse_args(argv)
    return {"run": run, "digest": digest, "compare": compare}[args.mode](args)


if __name__ == "__main__":
    sys.exit(main())
