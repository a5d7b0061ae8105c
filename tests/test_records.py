"""Records that are valid JSON of the wrong shape — ``dataset.json``, ``pairset.json``, a training
run's and an rl run's ``state.json`` and ``config.json`` — are one line and a non-zero exit in
every command that reads them (``verify``: a FAULT line), never a traceback, and nothing is
written. Each case runs the CLI as a user does."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.cli import assert_one_line_error, run_cli
from tests.mem_helpers import tiny_pairset, train_tiny
from tests.synthetic_data import make_dataset

ROOT = Path(__file__).resolve().parents[1]
SMOKE = (ROOT / "manifests" / "smoke.toml").read_text()
RL_TINY = ["--rollout", "32", "--batch-size", "32", "--episode-steps", "16",
           "--checkpoint-every", "32", "--no-progress"]


def _wrong(value: Any) -> Any:
    """A JSON value of another type than ``value``."""
    if isinstance(value, bool) or value is None:
        return "x"
    if isinstance(value, (int, float)):
        return "x"
    if isinstance(value, str):
        return 5
    if isinstance(value, dict):
        return []
    return {}


HEADER = ("format", "format_version")


def _top(record: Any) -> Any:
    """Every top-level value (but the format header) of another type."""
    return {k: v if k in HEADER else _wrong(v) for k, v in record.items()}


def _deep(record: Any) -> Any:
    """The same objects, every value inside them (the header aside) of another type."""
    if isinstance(record, dict):
        return {k: v if k in HEADER else _deep(v) if isinstance(v, dict) else _wrong(v)
                for k, v in record.items()}
    return _wrong(record)


class Raw(str):
    """A record's text as it is, not a value to write as JSON."""


def _nested(record: Any) -> Raw:
    """The header, and a field nested 100,000 lists deep (Python's parser gives up at ~1,000)."""
    header = {k: record[k] for k in HEADER if isinstance(record, dict) and k in record}
    return Raw(json.dumps(header)[:-1] + (", " if header else "") + '"settings": '
               + "[" * 100_000 + "]" * 100_000 + "}")


def _infinite(record: Any) -> Raw:
    """Every number (the header's aside), at any depth, ``Infinity``: JSON that Python reads."""
    def inf(v: Any, key: str = "") -> Any:
        if isinstance(v, dict):
            return {k: inf(x, k) for k, x in v.items()}
        if isinstance(v, list):
            return [inf(x) for x in v]
        numeric = isinstance(v, (int, float)) and not isinstance(v, bool)
        return float("inf") if numeric and key not in HEADER else v
    return Raw(json.dumps(inf(record)))


BAD: dict[str, Callable[[Any], Any]] = {
    "list": lambda r: [], "empty": lambda r: {}, "foreign": lambda r: {"episodes": "x"},
    "null": lambda r: None, "number": lambda r: 3, "string": lambda r: "x",
    "top-types": _top, "deep-types": _deep, "nested": _nested, "infinite": _infinite,
}
"""Bad contents, made from the good record."""

# The commands that read each record: (the folder whose record is bad, argv). {folder} is a copy
# of that folder, {tmp} a scratch folder, {build} a build folder holding the dataset as its
# rollout, {recipe} a recipe for the dataset, {run}/{pairs} a good run and pair set.
TRAIN = ["--epochs", "2", "--threads", "1", "--vocab-size", "2000", "--no-progress"]
READERS: dict[str, tuple[str, dict[str, tuple[str, list[str]]]]] = {
    "dataset": ("dataset.json", {
        "info": ("data", ["info", "{folder}"]),
        "verify": ("data", ["verify", "{folder}"]),
        "label": ("data", ["label", "{folder}", "--no-progress"]),
        "pair": ("data", ["pair", "{recipe}", "--data", "{folder}", "--out", "{tmp}/p",
                          "--no-progress"]),
        "rollout": ("data", ["rollout", "--out", "{folder}", "--agent", "random", "--episodes",
                             "3", "--seed", "7", "--episodes-per-shard", "1", "--no-progress"]),
        "build": ("data", ["build", "{recipe}", "--out", "{build}", "--no-progress"]),
    }),
    "pairset": ("pairset.json", {
        "info": ("pairs", ["info", "{folder}"]),
        "verify": ("pairs", ["verify", "{folder}"]),
        "train": ("pairs", ["train", "{folder}", "--out", "{tmp}/r", *TRAIN]),
        "evaluate": ("pairs", ["evaluate", "{run}", "--data", "{folder}"]),
        "tsne": ("pairs", ["tsne", "{run}", "--data", "{folder}", "--out", "{tmp}/t.png",
                           "--states", "20"]),
    }),
    "run-state": ("state.json", {
        "info": ("run", ["info", "{folder}"]),
        "verify": ("run", ["verify", "{folder}"]),
        "train": ("unfinished", ["train", "{pairs}", "--out", "{folder}", *TRAIN]),
        "evaluate": ("run", ["evaluate", "{folder}"]),
        "tsne": ("run", ["tsne", "{folder}", "--out", "{tmp}/t.png", "--states", "20"]),
        "rl-train": ("run", ["rl", "train", "--out", "{tmp}/rl", "--reward", "narration",
                             "--mem", "{folder}", "--action-space", "paper", "--steps", "32",
                             *RL_TINY]),
    }),
    "run-config": ("config.json", {
        "info": ("run", ["info", "{folder}"]),
        "verify": ("run", ["verify", "{folder}"]),
        "train": ("unfinished", ["train", "{pairs}", "--out", "{folder}", *TRAIN]),
        "evaluate": ("run", ["evaluate", "{folder}"]),
        "tsne": ("run", ["tsne", "{folder}", "--out", "{tmp}/t.png", "--states", "20"]),
    }),
    "rl-state": ("state.json", {
        "rl-train": ("rl", ["rl", "train", "--out", "{folder}", "--seed", "1", "--steps", "64",
                            *RL_TINY]),
        "rl-evaluate": ("rl", ["rl", "evaluate", "{folder}", "--episodes", "1",
                               "--no-progress"]),
    }),
    "rl-config": ("config.json", {
        "rl-train": ("rl", ["rl", "train", "--out", "{folder}", "--seed", "1", "--steps", "64",
                            *RL_TINY]),
        "rl-evaluate": ("rl", ["rl", "evaluate", "{folder}", "--episodes", "1",
                               "--no-progress"]),
        "rl-plot": ("rl", ["rl", "plot", "{folder}", "--out", "{tmp}/c.png"]),
    }),
}


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One of each folder, whole and valid: a labelled dataset, a pair set, a finished and an
    unfinished training run, an rl run, and a recipe that describes the dataset."""
    from sc2data.ground.files import sha256_file
    from sc2data.labels.label import label_dataset
    from sc2data.rl.train import RLConfig
    from sc2data.rl.train import train as rl_train

    root = tmp_path_factory.mktemp("records")
    make_dataset(root / "data", episodes=3, per_shard=1)
    label_dataset(root / "data", progress=False)
    recipe = root / "recipe.toml"
    recipe.write_text(SMOKE.replace('agent = "reduced-random"', 'agent = "random"')
                      .replace("episodes = 20", "episodes = 3")
                      .replace("states_per_command = 40", "states_per_command = 3")
                      .replace("null_states = 200", "null_states = 12"))
    pairs = tiny_pairset(root / "pairs")
    run = train_tiny(pairs, root / "run", epochs=1)
    # A run of 2 epochs interrupted after its first, as state.json records it.
    unfinished = train_tiny(pairs, root / "unfinished", epochs=1)
    config = json.loads((unfinished / "config.json").read_text())
    (unfinished / "config.json").write_text(json.dumps({**config, "epochs": 2}, indent=2))
    state = json.loads((unfinished / "state.json").read_text())
    state.update(epochs=2, finished=False)
    state["sha256"]["config.json"] = sha256_file(unfinished / "config.json")
    (unfinished / "state.json").write_text(json.dumps(state))
    rl_train(RLConfig(out=str(root / "rl"), seed=1, steps=32, rollout=32, batch_size=32,
                      episode_steps=16, checkpoint_every=32, progress=False))
    return {"data": root / "data", "pairs": pairs, "run": run, "unfinished": unfinished,
            "rl": root / "rl", "recipe": recipe}


def _run(good: dict[str, Path], tmp: Path, kind: str, command: str,
         content: Callable[[Any], Any] | None, capsys: pytest.CaptureFixture[str]
         ) -> tuple[int, str, Path]:
    """Copy the command's folder into ``tmp``, give its record ``content`` (made from the good
    record; None: keep it) and run the command: (exit status, stderr, the record)."""
    name, commands = READERS[kind]
    which, argv = commands[command]
    folder = tmp / which
    shutil.copytree(good[which], folder)
    build = tmp / "build"
    if which == "data":  # a build folder whose rollout is this dataset
        shutil.copytree(good["data"], build / "rollout")
    for record in (folder / name, build / "rollout" / name):
        if content is not None and record.exists():
            bad = content(json.loads(record.read_text()))
            record.write_text(bad if isinstance(bad, Raw) else json.dumps(bad))
    code, _, err = run_cli([a.format(folder=folder, tmp=tmp, build=build, recipe=good["recipe"],
                                     run=good["run"], pairs=good["pairs"]) for a in argv], capsys)
    return code, err, folder / name


GETS_PAST = {"build": "holds a dataset made with other settings",  # the recipe's, not the
              "pair": "too few labelled states"}  # synthetic data's; no rule fires in it
"""The commands that cannot finish on the small synthetic dataset: the error they reach."""
CONTROLS = list({(commands[c][0], *commands[c][1]): (kind, c) for kind, (_, commands) in
                 READERS.items() for c in commands}.values())
"""One (kind, command) per distinct command line: several kinds share a command."""


@pytest.mark.parametrize("kind, command", CONTROLS, ids=[f"{k}-{c}" for k, c in CONTROLS])
def test_each_command_reads_the_good_record(good: dict[str, Path], tmp_path: Path, kind: str,
                                            command: str,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """The control: each command succeeds on the good folders, or gets past the record to a
    later check, so a bad record is what makes it fail below."""
    code, err, _ = _run(good, tmp_path, kind, command, None, capsys)
    if command in GETS_PAST:
        assert_one_line_error(code, err, GETS_PAST[command])
    else:
        assert code == 0, err


CASES = [pytest.param(kind, bad, command, id=f"{kind}-{bad}-{command}")
         for kind, (_, commands) in READERS.items() for bad in BAD for command in commands]


@pytest.mark.parametrize("kind, bad, command", CASES)
def test_wrong_shape_is_one_line(good: dict[str, Path], tmp_path: Path, kind: str, bad: str,
                                 command: str, capsys: pytest.CaptureFixture[str]) -> None:
    before: dict[Path, int] = {}

    def content(record: Any) -> Any:
        before.update({p: p.stat().st_mtime_ns for p in tmp_path.rglob("*") if p.is_file()})
        return BAD[bad](record)

    code, err, record = _run(good, tmp_path, kind, command, content, capsys)
    if command == "verify":
        assert code == 1, err
        assert "Traceback" not in err
        assert err.startswith("FAULT ") and record.name in err.splitlines()[0], err
    else:
        assert_one_line_error(code, err)
    written = {p for p in tmp_path.rglob("*") if p.is_file() and not p.name.endswith(".lock")
               and p.stat().st_mtime_ns != before.get(p) and p.name != record.name}
    assert not written, f"written: {sorted(map(str, written))}"
