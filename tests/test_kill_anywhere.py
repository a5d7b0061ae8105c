"""A real ``sc2data build`` and ``sc2data train``, stopped at a seeded random moment of their run
(``kill -9`` or Ctrl-C), then run again to the end: the result equals an uninterrupted
run's, byte for byte (shards, labels, pair set) or tensor for tensor (checkpoint, metrics).
So do ``export`` (npz, hf), a trained policy's ``rollout --agent policy:RUN`` and ``pair`` of a
mixed recipe (a reduced-random and a policy source); ``rl train``, which a resume seeds anew,
agrees with itself.

The moments are drawn uniformly over the uninterrupted run's own duration, start-up included, so
over the runs of the suite they land in every stage — importing, rolling out, labelling, drawing
and packing pairs, an epoch, its commit. Whatever moment a signal lands on, the assertions must
hold; the seed and moment are printed so a failure can be replayed. Linux only (signals).
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
def _recipe(name: str, *, states: int, nulls: int, sources: str = "") -> str:
    """A small recipe of two commands (``sources``: TOML tables of a mixed recipe)."""
    return f"""
name = "{name}"
seed = 3

[rollout]
env = "sim"
agent = "reduced-random"
episodes = 3
layers = "paper"
{sources}
[commands.build_scv]
text = "build an SCV"

[commands.collect_minerals]
text = "collect minerals"

[pairs]
states_per_command = {states}
null_states = {nulls}

[split]
method = "random"
train = 0.6
val = 0.2
test = 0.2
"""


RECIPE = _recipe("killed", states=30, nulls=60)
TRAIN = ["--epochs", "2", "--vocab-size", "2000", "--threads", "1", "--batch-size", "16"]
SIGNALS = (signal.SIGKILL, signal.SIGINT)
"""What stops a run: ``kill -9`` or Ctrl-C, drawn with the moment."""

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(sys.platform != "linux", reason="needs Linux signals")]


SEED = int(os.environ.get("SC2DATA_KILL_SEED", time.time_ns() % 2**32))
"""Seed of the moments: set ``SC2DATA_KILL_SEED`` to replay a run's draws (printed on failure)."""


def _sc2data(*args: object) -> list[str]:
    return [sys.executable, "-m", "sc2data.cli", *map(str, args)]


def _cli(*args: object) -> list[str]:
    """A long-running command, without progress lines."""
    return _sc2data(*args, "--no-progress")


def _run(args: list[str]) -> float:
    """Run to the end; its wall time."""
    t0 = time.monotonic()
    done = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return time.monotonic() - t0


def _stop_at(args: list[str], seconds: float, sig: int) -> bool:
    """Start ``args`` and send ``sig`` after ``seconds``; a Ctrl-C must end in exit 130 and one
    line, a kill in the kill. False when the run finished before the signal."""
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True,  # SIGINT as a terminal job has it
                            preexec_fn=lambda: signal.signal(  # noqa: PLW1509 - one signal() call
                                signal.SIGINT, signal.SIG_DFL))
    time.sleep(seconds)
    if proc.poll() is None:
        proc.send_signal(sig)
    _, err = proc.communicate(timeout=300)
    if proc.returncode == 0:
        return False
    if sig == signal.SIGINT and _as_python_started(proc.returncode, err):
        print("the Ctrl-C landed as Python started, before sc2data's handler: Python's own "
              "ending (a known gap, docs/reliability.md)")
        return True
    assert "Traceback" not in err, err
    if sig == signal.SIGINT:
        assert proc.returncode == 130, err
        assert err.strip().splitlines()[-1] == \
            "sc2data: interrupted; rerun the same command to resume", err
    else:
        assert proc.returncode == -signal.SIGKILL, err
    return True


def _as_python_started(returncode: int, err: str) -> bool:
    """A Ctrl-C in the first milliseconds, while the interpreter starts (site, runpy), before
    ``sc2data.cli.main`` takes SIGINT: killed by it, or a ``KeyboardInterrupt`` traceback that
    never passed through ``main`` (which turns any later one into 130 and one line)."""
    if returncode == -signal.SIGINT:
        return not err.strip()
    return returncode != 130 and err.rstrip().endswith("KeyboardInterrupt") and \
        re.search(r'sc2data/cli/__init__\.py", line \d+, in main\n', err) is None


def _stopped_then_finished(args: list[str], duration: float, rng: random.Random) -> None:
    """Stop ``args`` once at a drawn moment by a drawn signal, then run it to the end."""
    moment, sig = rng.uniform(0.0, duration), rng.choice(SIGNALS)
    print(f"SC2DATA_KILL_SEED={SEED}: stopping {args[3]} at {moment:.2f} s of {duration:.2f} s "
          f"({'kill -9' if sig == signal.SIGKILL else 'Ctrl-C'})")
    if _stop_at(args, moment, sig):
        _run(args)
    else:
        print("it finished before the signal")


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _build_content(out: Path) -> dict[str, str]:
    """Every file whose bytes a build's result is: shards, packed splits, pairs; the labels'
    content (their files also record when they were made)."""
    import pyarrow.parquet as pq

    files = {str(p.relative_to(out)): _sha(p) for p in sorted(out.rglob("*.h5"))}
    files["pairs.parquet"] = _sha(out / "pairs" / "pairs.parquet")
    for name in ("labels.parquet", "stack_labels.parquet"):
        table = pq.read_table(out / "rollout" / name)
        files[name] = hashlib.sha256(str(table.to_pydict()).encode()).hexdigest()
    return files


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, float, float]:
    """An uninterrupted build and training run, and how long each took."""
    root = tmp_path_factory.mktemp("kill-ref")
    recipe = root / "recipe.toml"
    recipe.write_text(RECIPE)
    build_s = _run(_cli("build", recipe, "--out", root / "build", "--workers", "1"))
    train_s = _run(_cli("train", root / "build" / "pairs", "--out", root / "run", *TRAIN))
    return recipe, root, build_s, train_s


def test_build_stopped_anywhere_finishes_to_the_same_bytes(
        reference: tuple[Path, Path, float, float], tmp_path: Path) -> None:
    recipe, root, build_s, _ = reference
    args = _cli("build", recipe, "--out", tmp_path / "build", "--workers", "1")
    _stopped_then_finished(args, build_s, random.Random(f"build {SEED}"))
    assert _build_content(tmp_path / "build") == _build_content(root / "build")
    done = subprocess.run(_sc2data("verify", tmp_path / "build" / "pairs"), cwd=ROOT,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_train_stopped_anywhere_finishes_to_the_same_model(
        reference: tuple[Path, Path, float, float], tmp_path: Path) -> None:
    import torch

    _, root, _, train_s = reference
    args = _cli("train", root / "build" / "pairs", "--out", tmp_path / "run", *TRAIN)
    _stopped_then_finished(args, train_s, random.Random(f"train {SEED}"))
    keep = ("epoch", "train_loss", "train_acc", "val_loss", "val_acc", "l2", "best")
    rows = [[{k: r[k] for k in keep} for r in map(json.loads, (run / "metrics.jsonl").open())]
            for run in (root / "run", tmp_path / "run")]
    assert rows[0] == rows[1]
    a, b = (torch.load(run / "best.pt", weights_only=True)["state_dict"]
            for run in (root / "run", tmp_path / "run"))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert json.loads((tmp_path / "run" / "state.json").read_text())["finished"] is True
    done = subprocess.run(_sc2data("verify", tmp_path / "run"), cwd=ROOT, capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr


RL = ["rl", "train", "--steps", "192", "--rollout", "32", "--batch-size", "32",
      "--episode-steps", "25", "--checkpoint-every", "64"]


@pytest.mark.parametrize("envs", [1, 2])
def test_rl_train_stopped_anywhere_resumes_to_a_run_that_agrees_with_itself(
        tmp_path: Path, envs: int) -> None:
    """An RL run cannot equal an uninterrupted one (a resume seeds its games anew), but after a
    stop anywhere and the rerun, its model, curve and state agree with each other (the sha256
    the last checkpoint recorded) and with its settings, it trained for its --steps, and it
    evaluates."""
    from sc2data.rl import runs

    ref = tmp_path / "ref"
    args = [*RL, "--envs", envs, "--processes", envs]
    duration = _run(_cli(*args, "--out", ref))
    out = tmp_path / "run"
    _stopped_then_finished(_cli(*args, "--out", out), duration, random.Random(f"rl {envs} {SEED}"))
    state = runs.read_state(out)  # raises unless model.zip and curve.csv are the recorded ones
    assert state is not None and state["timesteps"] >= 192
    rows = runs.read_curve(out)
    assert all(r["timesteps"] <= state["timesteps"] for r in rows)
    assert len(rows) == state["episodes"] and [r["episode"] for r in rows] == list(
        range(1, len(rows) + 1))
    assert not list(out.glob("*.partial*"))
    done = subprocess.run(_sc2data("rl", "evaluate", out, "--episodes", "1", "--no-progress"),
                          cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def _verifies(path: Path) -> None:
    done = subprocess.run(_sc2data("verify", path), cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("to", ["npz", "hf"])
def test_export_stopped_anywhere_finishes_to_the_same_export(
        reference: tuple[Path, Path, float, float], tmp_path: Path, to: str) -> None:
    """``export`` of the reference build's rollout, stopped anywhere and rerun, equals an
    uninterrupted export file for file (the files are deterministic: a Hugging Face dataset's
    ``state.json`` aside, whose ``_fingerprint`` datasets draws at random) and in content, and
    leaves no ``*.partial*`` beside ``--out``. A kill after the rename leaves ``OUT`` whole: the
    rerun exports it again rather than refusing it."""
    if to == "hf":
        datasets = pytest.importorskip("datasets")
    _, root, _, _ = reference
    # An hf row holds both frames of a stack, uncompressed: one episode is 370 MB, three 1.1 GB.
    some = ["--episodes", "1"] if to == "hf" else []
    ref, out = tmp_path / "ref", tmp_path / "out"
    duration = _run(_cli("export", root / "build" / "rollout", "--to", to, "--out", ref, *some))
    _stopped_then_finished(_cli("export", root / "build" / "rollout", "--to", to, "--out", out,
                                *some), duration, random.Random(f"export {to} {SEED}"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "ref"]  # no *.partial* beside
    files = [{str(p.relative_to(d)): _sha(p) for p in sorted(d.rglob("*"))
              if p.is_file() and p.name != "state.json"} for d in (ref, out)]
    assert files[0] == files[1] and "metadata.json" in files[0]
    if to == "npz":
        import numpy as np

        assert len(files[0]) == 4  # three episodes and metadata.json
        for name in (n for n in files[0] if n.endswith(".npz")):
            with np.load(ref / name) as a, np.load(out / name) as b:
                assert a.files == b.files
                assert all(np.array_equal(a[k], b[k]) and a[k].dtype == b[k].dtype
                           for k in a.files), name
    else:
        a, b = (datasets.load_from_disk(str(d / "dataset")) for d in (ref, out))
        assert a.features == b.features and len(a) == len(b) > 0
        assert a.data.table.equals(b.data.table)  # every row, column for column
        del a, b
        shutil.rmtree(tmp_path)  # 740 MB


POLICY_RUN = ["rl", "train", "--steps", "64", "--rollout", "32", "--batch-size", "32",
              "--episode-steps", "25", "--envs", "1"]
MIXED = _recipe("killed-mixed", states=8, nulls=20, sources="""
[sources.random]
share = 0.5

[sources.policy]
share = 0.5
agent = AGENT
""")


def _policy_rollout(run: Path, out: Path) -> list[str]:
    return _cli("rollout", "--agent", f"policy:{run}", "--episodes", "3", "--max-steps", "100",
                "--workers", "1", "--episodes-per-shard", "1", "--out", out)


def _rollout_content(out: Path) -> dict[str, str]:
    """A rollout's shards by their bytes, and its index's content."""
    import pyarrow.parquet as pq

    files = {p.name: _sha(p) for p in sorted(out.glob("*.h5"))}
    files["index.parquet"] = str(pq.read_table(out / "index.parquet").to_pydict())
    return files


@pytest.fixture(scope="module")
def policy(reference: tuple[Path, Path, float, float],
           tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, float, float]:
    """A tiny trained rl run (``RUN``), its policy's uninterrupted rollout ``DIR/policy`` and the
    reference build's reduced-random rollout copied to ``DIR/random``, both labelled; the mixed
    recipe drawing from them, its uninterrupted pair set ``ROOT/pairs``; how long the rollout
    and the pair took."""
    root = tmp_path_factory.mktemp("kill-policy")
    _run(_cli(*POLICY_RUN, "--out", root / "rl"))
    sources = root / "sources"
    rollout_s = _run(_policy_rollout(root / "rl", sources / "policy"))
    _run(_cli("label", sources / "policy"))
    shutil.copytree(reference[1] / "build" / "rollout", sources / "random",
                    ignore=shutil.ignore_patterns(".lock"))
    recipe = root / "mixed.toml"
    recipe.write_text(MIXED.replace("AGENT", json.dumps(f"policy:{root / 'rl'}")))
    pair_s = _run(_cli("pair", recipe, "--data", sources, "--out", root / "pairs"))
    return root, recipe, rollout_s, pair_s


def test_policy_rollout_stopped_anywhere_finishes_to_the_same_bytes(
        policy: tuple[Path, Path, float, float], tmp_path: Path) -> None:
    """``rollout --agent policy:RUN`` (the MEM loop's rollouts of a trained policy), stopped
    anywhere and rerun: the shards equal an uninterrupted rollout's byte for byte."""
    root, _, rollout_s, _ = policy
    out = tmp_path / "policy"
    _stopped_then_finished(_policy_rollout(root / "rl", out), rollout_s,
                           random.Random(f"policy {SEED}"))
    assert _rollout_content(out) == _rollout_content(root / "sources" / "policy")
    assert len(list(out.glob("*.h5"))) == 3 and not list(out.glob("*.partial*"))
    _verifies(out)


def test_mixed_pair_stopped_anywhere_finishes_to_the_same_bytes(
        policy: tuple[Path, Path, float, float], tmp_path: Path) -> None:
    """``pair`` of a mixed recipe (a reduced-random source and a policy source), stopped
    anywhere and rerun: the pairs and packed splits equal an uninterrupted run's byte for
    byte."""
    root, recipe, _, pair_s = policy
    out = tmp_path / "pairs"
    _stopped_then_finished(_cli("pair", recipe, "--data", root / "sources", "--out", out),
                           pair_s, random.Random(f"pair {SEED}"))
    files = [{str(p.relative_to(d)): _sha(p) for p in sorted(d.rglob("*.h5"))}
             | {"pairs.parquet": _sha(d / "pairs.parquet")} for d in (root / "pairs", out)]
    assert files[0] == files[1] and len(files[0]) == 4  # pairs and three packed splits
    import pyarrow.parquet as pq

    assert set(pq.read_table(out / "pairs.parquet")["source"].to_pylist()) == {"random",
                                                                              "policy"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pairs"]  # nothing beside it
    _verifies(out)
