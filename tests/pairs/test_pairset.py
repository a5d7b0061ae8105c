"""``sc2data build`` and ``sc2data pair`` on a real (small) simulator rollout, through the CLI."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from sc2data.data.dataset import open_dataset
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.vocab import SPLITS
from sc2data.pairs.packed import PackedSplit
from tests.cli import assert_one_line_error, exit_code, run_cli

ROOT = Path(__file__).resolve().parents[2]
SC2DATA = [sys.executable, "-m", "sc2data.cli"]

RECIPE = (ROOT / "manifests" / "smoke.toml").read_text()


def recipe_file(folder: Path, **changes: str) -> Path:
    """The smoke recipe with some lines replaced (``key=value`` as TOML text)."""
    text = RECIPE
    for key, value in changes.items():
        lines = text.splitlines()
        hits = [i for i, l in enumerate(lines) if l.startswith(f"{key} = ")]
        assert hits, key
        lines[hits[0]] = f"{key} = {value}"
        text = "\n".join(lines) + "\n"
    path = folder / "recipe.toml"
    path.write_text(text)
    return path


def run(*args: object, ok: bool = True) -> subprocess.CompletedProcess[str]:
    p = subprocess.run([*SC2DATA, *map(str, args)], capture_output=True, text=True, cwd=ROOT)
    if ok:
        assert p.returncode == 0, p.stderr
    return p


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3-episode build of a small recipe: OUT/rollout (labelled) and OUT/pairs."""
    tmp = tmp_path_factory.mktemp("build")
    recipe = recipe_file(tmp, episodes="3", states_per_command="3", null_states="12")
    run("build", recipe, "--out", tmp / "out", "--workers", "2", "--no-progress")
    return tmp / "out"


def test_build_makes_every_stage(built: Path) -> None:
    meta = json.loads((built / "pairs" / "pairset.json").read_text())
    assert meta["format"] == "sc2data.pairset" and meta["seed"] == 0
    assert [c["id"] for c in meta["commands"]] == ["build_scv", "collect_minerals",
                                                  "build_supply_depot", "build_barracks",
                                                  "train_marine"]
    pairs = pq.read_table(built / "pairs" / "pairs.parquet").to_pydict()
    assert pairs["kind"].count("matched") == 5 * 3
    assert pairs["kind"].count("mismatched") == 5 * 3
    assert pairs["kind"].count("null") == 12
    assert meta["versions"]["sc2data"] and meta["schema"]["version"] == 1


def test_rerun_build_resumes_without_redoing(built: Path, tmp_path: Path) -> None:
    recipe = recipe_file(tmp_path, episodes="3", states_per_command="3", null_states="12")
    before = (built / "pairs" / "pairset.json").stat().st_mtime_ns
    p = run("build", recipe, "--out", built, "--no-progress")
    assert "0 shards written, 1 kept" in p.stdout
    assert ("up to date" in p.stdout
            or (built / "pairs" / "pairset.json").stat().st_mtime_ns == before)


def test_packed_stacks_equal_the_rollout(built: Path) -> None:
    pairs = pq.read_table(built / "pairs" / "pairs.parquet").to_pydict()
    ds = open_dataset(built / "rollout")
    for split in SPLITS:
        rows = [i for i, s in enumerate(pairs["split"]) if s == split]
        with PackedSplit(built / "pairs" / "packed" / f"{split}.h5") as packed:
            assert len(packed) == len({pairs["state"][i] for i in rows})
            for i in rows[:8]:
                got = packed.read(pairs["state"][i], pairs["state"][i] + 1)
                want = ds.stack(pairs["episode"][i], pairs["step"][i])
                for key in ds.schema.keys():
                    np.testing.assert_array_equal(got.arrays[key], want.arrays[key])


def test_pair_is_deterministic_and_up_to_date(built: Path, tmp_path: Path) -> None:
    recipe = recipe_file(tmp_path, episodes="3", states_per_command="3", null_states="12")
    run("pair", recipe, "--data", built / "rollout", "--out", tmp_path / "a", "--no-progress")
    a = pq.read_table(tmp_path / "a" / "pairs.parquet")
    assert a.equals(pq.read_table(built / "pairs" / "pairs.parquet"))
    p = run("pair", recipe, "--data", built / "rollout", "--out", tmp_path / "a", "--no-progress")
    assert "up to date" in p.stdout


def test_other_seed_other_pairs(built: Path, tmp_path: Path) -> None:
    recipe = recipe_file(tmp_path, seed="5", episodes="3", states_per_command="3",
                         null_states="12")
    # the seed is the recipe's, not the data's
    shutil.copytree(built / "rollout", tmp_path / "data")
    run("pair", recipe, "--data", tmp_path / "data", "--out", tmp_path / "b", "--no-progress")
    b = pq.read_table(tmp_path / "b" / "pairs.parquet")
    assert not b.equals(pq.read_table(built / "pairs" / "pairs.parquet"))


@pytest.mark.parametrize("changes,message", [
    ({"states_per_command": "5000"}, "too few labelled states for the recipe"),
    ({"episodes": "0"}, "[rollout].episodes must be a positive integer"),
    ({"mismatch": '"nearest"'}, "[pairs].mismatch must be one of uniform"),
])
def test_pair_errors_are_one_line(built: Path, tmp_path: Path, changes: dict[str, str],
                                  message: str) -> None:
    recipe = recipe_file(tmp_path, **changes)
    p = run("pair", recipe, "--data", built / "rollout", "--out", tmp_path / "x", ok=False)
    assert p.returncode == 2
    assert message in p.stderr
    assert p.stderr.count("\n") == 1 and "Traceback" not in p.stderr
    assert not (tmp_path / "x").exists() and not (tmp_path / ".x.partial").exists()


GROW_RECIPE = """
name = "grow"
seed = 0

[rollout]
env = "sim"
agent = "reduced-random"
episodes = 3
layers = "paper"

[commands.build_scv]
text = "build an SCV"

[commands.build_supply_depot]
text = "build a supply depot"

[pairs]
states_per_command = 12
null_states = 40

[split]
method = "episode"
train = 0.6
val = 0.2
test = 0.2
"""


def test_a_shortage_gives_the_command_that_grows_the_data_enough(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Too few states: one line with the recipe's totals and a runnable command; once it has run,
    pair succeeds (and not from labels of the data before it grew)."""
    data, recipe = tmp_path / "data", tmp_path / "grow.toml"
    recipe.write_text(GROW_RECIPE)
    assert exit_code("rollout", "--out", data, "--episodes", "3", "--episodes-per-shard", "2",
                     "--max-steps", "200", "--no-progress") == 0
    assert exit_code("label", data, "--no-progress") == 0
    code, _, err = run_cli(["pair", recipe, "--data", data, "--out", tmp_path / "p"], capsys)
    assert_one_line_error(code, err, "grow the data: ")
    assert re.search(r": build_scv \d+ of 12 the recipe asks for, build_supply_depot \d+ of 12 "
                     r"the recipe asks for \(in 3 episodes\); grow the data: ", err)
    command = err.strip().split("; grow the data: ")[1]
    assert command == (f"sc2data rollout --out {data} --episodes "
                       f"{int(command.split()[5])} && sc2data label {data}")
    grow, relabel = command.split(" && ")
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    subprocess.run(grow, shell=True, check=True, cwd=ROOT, capture_output=True, env=env)
    code, _, err = run_cli(["pair", recipe, "--data", data, "--out", tmp_path / "p"], capsys)
    assert_one_line_error(code, err, "are of other data than it holds now (it grew")
    subprocess.run(relabel, shell=True, check=True, cwd=ROOT, capture_output=True, env=env)
    code, out, err = run_cli(["pair", recipe, "--data", data, "--out", tmp_path / "p",
                              "--no-progress"], capsys)
    assert code == 0 and "pair set written" in out, err


def test_pair_refuses_unlabelled_data_and_foreign_output(built: Path, tmp_path: Path) -> None:
    recipe = recipe_file(tmp_path, episodes="3", states_per_command="3", null_states="12")
    p = run("pair", recipe, "--data", tmp_path, ok=False)
    assert p.returncode == 2 and "is not an sc2data dataset" in p.stderr
    shutil.copytree(built / "rollout", tmp_path / "data", ignore=shutil.ignore_patterns("*label*"))
    p = run("pair", recipe, "--data", tmp_path / "data", ok=False)
    assert p.returncode == 2 and "no labels in" in p.stderr
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "notes.txt").write_text("mine")
    p = run("pair", recipe, "--data", built / "rollout", "--out", tmp_path / "busy", ok=False)
    assert p.returncode == 2 and "already holds something other" in p.stderr
    assert (tmp_path / "busy" / "notes.txt").read_text() == "mine"


def test_pair_names_a_command_the_labels_lack(built: Path, tmp_path: Path) -> None:
    text = RECIPE.replace("[commands.train_marine]", "[commands.build_factory]")
    (tmp_path / "r.toml").write_text(text)
    p = run("pair", tmp_path / "r.toml", "--data", built / "rollout", ok=False)
    assert p.returncode == 2 and "have no rule build_factory" in p.stderr


def test_recipe_text_must_be_the_rules_command(tmp_path: Path) -> None:
    """labels.parquet records the rule's command, pairs.parquet the recipe's text: they agree."""
    from sc2data.ground.recipe import parse
    from sc2data.pairs.pairset import check_texts

    recipe = parse(tomllib.loads(RECIPE.replace('text = "train a marine"',
                                                'text = "train a trooper"')), "t.toml")
    rules = {c.id: c.text for c in recipe.commands} | {"train_marine": "train a marine"}
    with pytest.raises(Sc2DataError, match="command train_marine has text 'train a trooper', but "
                                           "rule train_marine says 'train a marine'"):
        check_texts(recipe, rules)
    check_texts(recipe, rules | {"train_marine": "train a trooper"})  # agreeing: no error


def test_damaged_pair_set_is_rebuilt_not_up_to_date(built: Path, tmp_path: Path) -> None:
    """A flipped byte in a packed split: pair rebuilds it (no "up to date" beside a trainer that
    refuses it), equal to the original."""
    recipe = recipe_file(tmp_path, episodes="3", states_per_command="3", null_states="12")
    out = tmp_path / "a"
    shutil.copytree(built / "pairs", out)
    good = (out / "packed" / "train.h5").read_bytes()
    with open(out / "packed" / "train.h5", "r+b") as f:
        f.seek(-64, 2)
        b = f.read(1)
        f.seek(-64, 2)
        f.write(bytes([b[0] ^ 1]))
    p = run("pair", recipe, "--data", built / "rollout", "--out", out, "--no-progress")
    assert "up to date" not in p.stdout
    assert (out / "packed" / "train.h5").read_bytes() == good


def test_relabel_with_identical_content_keeps_the_pair_set(built: Path, tmp_path: Path) -> None:
    """The pair set is tied to the labels' content, not to when they were made."""
    recipe = recipe_file(tmp_path, episodes="3", states_per_command="3", null_states="12")
    data = tmp_path / "rollout"
    shutil.copytree(built / "rollout", data)
    run("pair", recipe, "--data", data, "--out", tmp_path / "a", "--no-progress")
    for name in ("labels.parquet", "stack_labels.parquet", "labels.sha256"):
        (data / name).unlink()
    run("label", data, "--no-progress")
    p = run("pair", recipe, "--data", data, "--out", tmp_path / "a", "--no-progress")
    assert "up to date" in p.stdout


def _as_drawn_by_older_rules(pairs: Path, data: Path, shards: str | None = None) -> None:
    """Rewrite ``pairs``' record as an earlier sc2data wrote it from labels whose build_scv rule
    had other code (a docstring changed): that rule's code hash, the labels' fingerprint from it
    (on ``shards``, default the data's own), and ``labels_created`` in its identity."""
    from sc2data.labels.apply import labels_fingerprint
    from sc2data.labels.store import read_meta

    meta = json.loads((pairs / "pairset.json").read_text())
    rules = meta["labels"]["rules"]
    next(r for r in rules if r["id"] == "build_scv")["code_sha256"] = "0" * 64
    fp = labels_fingerprint(shards or read_meta(data)["dataset"]["fingerprint"],
                            [(r["id"], r["version"], r["code_sha256"]) for r in rules])
    meta["labels"]["fingerprint"] = fp
    meta["identity"].update(labels=fp, labels_created="2026-12-01T23:34:13+00:00")
    (pairs / "pairset.json").write_text(json.dumps(meta, indent=2))


def test_pair_set_from_older_rules_with_the_same_pairs_is_kept(built: Path,
                                                              tmp_path: Path) -> None:
    """A build folder whose pair set an earlier sc2data drew (its identity with the labels'
    creation time, the labels since remade because a rule's code changed): the same shards and
    the same pairs, so the rerun keeps it, files untouched, and its record names these labels."""
    build = tmp_path / "build"
    shutil.copytree(built, build)
    _as_drawn_by_older_rules(build / "pairs", build / "rollout")
    before = {p: p.read_bytes() for p in (build / "pairs").rglob("*") if p.suffix != ".json"
              and p.is_file()}
    recipe = recipe_file(tmp_path, episodes="3", states_per_command="3", null_states="12")
    run("build", recipe, "--out", build, "--no-progress")
    assert {p: p.read_bytes() for p in before} == before
    meta = json.loads((build / "pairs" / "pairset.json").read_text())
    assert meta["identity"] == json.loads((built / "pairs" / "pairset.json").read_text())[
        "identity"]
    run("verify", build / "pairs")


def test_pair_set_from_other_labels_is_refused_saying_so(built: Path, tmp_path: Path) -> None:
    """Drawn from other labels (other shards, or other verdicts): one line that says so and which
    rules changed, and what to do; nothing changed. Another recipe's pair set is named."""
    pairs = tmp_path / "pairs"
    shutil.copytree(built / "pairs", pairs)
    _as_drawn_by_older_rules(pairs, built / "rollout", shards="other shards")
    record = (pairs / "pairset.json").read_bytes()
    recipe = recipe_file(tmp_path, episodes="3", states_per_command="3", null_states="12")
    p = run("pair", recipe, "--data", built / "rollout", "--out", pairs, ok=False)
    assert p.returncode == 2 and p.stderr.count("\n") == 1, p.stderr
    assert "from other labels than" in p.stderr and "rule(s) build_scv changed" in p.stderr
    assert "delete it to draw it again" in p.stderr
    assert (pairs / "pairset.json").read_bytes() == record
    other = recipe_file(tmp_path, episodes="3", states_per_command="3", null_states="12",
                        name='"other"')
    p = run("pair", other, "--data", built / "rollout", "--out", built / "pairs", ok=False)
    assert p.returncode == 2 and "holds the pair set of recipe 'smoke', not 'other'" in p.stderr


def test_verify_covers_dataset_labels_and_pair_set(built: Path, tmp_path: Path) -> None:
    p = run("verify", built / "rollout")
    assert "OK (dataset; labels checked)" in p.stdout
    assert "OK (pair set)" in run("verify", built / "pairs").stdout
    data = tmp_path / "rollout"
    shutil.copytree(built / "rollout", data)
    with open(data / "stack_labels.parquet", "r+b") as f:  # labels damaged: verify says so
        f.seek(50)
        b = f.read(1)
        f.seek(50)
        f.write(bytes([b[0] ^ 0xFF]))
    p = run("verify", data, ok=False)
    assert p.returncode == 1 and "stack_labels.parquet is damaged" in p.stderr
    pairs = tmp_path / "pairs"
    shutil.copytree(built / "pairs", pairs)
    (pairs / "packed" / "val.h5").write_bytes(b"")
    p = run("verify", pairs, ok=False)
    assert p.returncode == 1 and "damaged or was replaced" in p.stderr
    p = run("verify", tmp_path / "nothing-here", ok=False)
    assert p.returncode == 2 and "not a folder sc2data writes" in p.stderr


def test_pair_refuses_a_recipe_whose_rollout_is_not_the_datas(built: Path, tmp_path: Path) -> None:
    recipe = recipe_file(tmp_path, episodes="3", states_per_command="3", null_states="12",
                         agent='"scripted"')
    p = run("pair", recipe, "--data", built / "rollout", "--out", tmp_path / "a", ok=False)
    assert p.returncode == 2 and "agent 'reduced-random' (recipe: 'scripted')" in p.stderr
    assert not (tmp_path / "a").exists()


def test_info_describes_every_folder(built: Path, tmp_path: Path) -> None:
    p = run("info", built / "rollout")
    assert "marines per episode (the game's score, from the index)" in p.stdout
    assert "build_scv" in p.stdout and "(null)" in p.stdout  # labels per rule
    p = run("info", built / "pairs")
    assert "recipe    " in p.stdout and "matched" in p.stdout and "'build an SCV'" in p.stdout
    p = run("info", tmp_path, ok=False)
    assert p.returncode == 2 and "not a dataset (sc2data rollout), pair set" in p.stderr
    assert run("--version").stdout.startswith("sc2data ")


def _without_training_phrasings(folder: Path, **changes: str) -> Path:
    path = recipe_file(folder, **changes)
    path.write_text("".join(l for l in path.read_text().splitlines(keepends=True)
                            if not l.startswith("train_paraphrases")))
    return path


def test_training_phrasings_change_only_the_train_texts_of_the_same_pairs(
        built: Path, tmp_path: Path) -> None:
    plain = _without_training_phrasings(tmp_path, episodes="3", states_per_command="3",
                                        null_states="12")
    run("pair", plain, "--data", built / "rollout", "--out", tmp_path / "plain", "--no-progress")
    a = pq.read_table(tmp_path / "plain" / "pairs.parquet").to_pydict()
    b = pq.read_table(built / "pairs" / "pairs.parquet").to_pydict()
    assert {k: v for k, v in a.items() if k != "command"} == \
        {k: v for k, v in b.items() if k != "command"}
    recipe = tomllib.loads(RECIPE)["commands"]
    held = {p for c in recipe.values() for p in c["paraphrases"]}
    for split, cid, text, canon in zip(b["split"], b["command_id"], b["command"], a["command"]):
        assert text not in held
        if split == "train":
            assert text in [recipe[cid]["text"], *recipe[cid]["train_paraphrases"]]
        else:
            assert text == canon == recipe[cid]["text"]
    meta = json.loads((built / "pairs" / "pairset.json").read_text())
    assert meta["commands"][0]["train_paraphrases"] == recipe["build_scv"]["train_paraphrases"]
    assert "train_paraphrases" not in meta["identity"]["recipe"]["commands"][0] or \
        meta["identity"]["recipe"]["commands"][0]["train_paraphrases"]
    old = json.loads((tmp_path / "plain" / "pairset.json").read_text())
    assert "train_paraphrases" not in old["identity"]["recipe"]["commands"][0]


def test_a_phrase_in_both_lists_stops_pair_with_one_line(built: Path, tmp_path: Path) -> None:
    path = recipe_file(tmp_path, episodes="3", states_per_command="3", null_states="12")
    path.write_text(path.read_text().replace('paraphrases = ["construct an scv"',
                                             'paraphrases = ["make an scv"', 1))
    p = run("pair", path, "--data", built / "rollout", "--out", tmp_path / "p", ok=False)
    assert p.returncode != 0 and "Traceback" not in p.stderr
    assert p.stderr.strip().count("\n") == 0
    assert "'make an scv' is already train_paraphrases 'make an scv'" in p.stderr
    assert not (tmp_path / "p").exists()
