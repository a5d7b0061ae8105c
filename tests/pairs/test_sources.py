"""Recipes that draw from several datasets (``[sources.NAME]``), and one that draws from one."""

from __future__ import annotations

import hashlib
import json
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pytest

from sc2data.ground.recipe import RecipeError, apportion, parse
from sc2data.ground.vocab import SPLITS
from sc2data.pairs import pairset
from sc2data.pairs.draw import Labelled, NotEnoughStates, build_pairs
from sc2data.rulebase import schema_for
from sc2data.schema import StackBatch

ROOT = Path(__file__).resolve().parents[2]
ONE_SOURCE_DIGEST = "2828fe844ab1c70efbc48dca121217ba126a55558f6bfab39a0eb371c550b2cd"
"""The pairs (with their packed rows) a one-source recipe drew before recipes had sources
(sc2data at b2da089): a recipe of one source draws them still, byte for byte."""


class _Stub:
    """A dataset of only ``player``, each stack stamped with its episode and step."""

    schema = schema_for(["player"])

    def read(self, episodes: np.ndarray, steps: np.ndarray) -> StackBatch:
        arrays = {v.name: np.zeros((len(episodes), 2, v.size), v.dtype)
                  for v in self.schema.vectors}
        arrays["player"][:, :, 0] = np.asarray(episodes)[:, None]
        arrays["player"][:, :, 1] = np.asarray(steps)[:, None]
        return StackBatch(arrays, self.schema)


class _Quiet:
    def update(self, n: int) -> None:
        pass


def labelled(seed: int = 3, episodes: int = 12, steps: int = 40) -> Labelled:
    """Labels drawn at random, each of the five commands at its own rate."""
    rng = np.random.default_rng(seed)
    ep = np.repeat(np.arange(episodes), steps).astype(np.int64)
    st = np.tile(np.arange(steps), episodes).astype(np.int32)
    fires = rng.random((len(ep), 5)) < np.array([0.1, 0.2, 0.05, 0.06, 0.1])
    return Labelled(ep, st, fires)


def smoke(**changes: Any) -> dict[str, Any]:
    data = tomllib.loads((ROOT / "manifests" / "smoke.toml").read_text())
    data["pairs"].update(states_per_command=6, null_states=30)
    data.update(changes)
    return data


def packed_rows(recipe: Any, pairs: pa.Table, tmp: Path, datasets: Any = None,
                names: tuple[str, ...] = ()) -> pa.Table:
    """The pairs with their ``state`` rows, as ``sc2data pair`` packs them."""
    parts = []
    for split in SPLITS:
        sub = pairs.filter(pc.equal(pairs["split"], split))
        part, _ = pairset._pack_split(datasets or _Stub(), split, sub, tmp / f"{split}.h5",
                                      recipe.seed, _Quiet(), names)
        parts.append(part)
    return pa.concat_tables(parts)


def test_a_recipe_of_one_source_draws_what_it_always_drew(tmp_path: Path) -> None:
    recipe = parse(smoke())
    assert "sources" not in recipe.to_dict()  # its identity (pair sets up to date) unchanged
    table = packed_rows(recipe, build_pairs(recipe, labelled()), tmp_path)
    digest = hashlib.sha256(json.dumps(table.to_pydict(), sort_keys=True).encode()).hexdigest()
    assert digest == ONE_SOURCE_DIGEST


def mixed(**shares: float) -> Any:
    return parse(smoke(sources={name: {"share": share} for name, share in shares.items()}))


def test_mixed_splits_are_episode_disjoint_per_source_with_each_its_share(
        tmp_path: Path) -> None:
    recipe = mixed(random=0.25, policy=0.75)
    a, b = labelled(seed=1), labelled(seed=2, episodes=9)  # episode numbers overlap
    pairs = build_pairs(recipe, [a, b])
    assert pairs.equals(build_pairs(recipe, [a, b]))  # deterministic
    cols = pairs.to_pydict()
    for name in ("random", "policy"):
        sides = [{e for e, s, src in zip(cols["episode"], cols["split"], cols["source"])
                  if s == split and src == name} for split in SPLITS]
        assert all(sides) and not (sides[0] & sides[1] or sides[0] & sides[2]
                                   or sides[1] & sides[2]), name
    quotas = apportion(recipe.pairs.states_per_command, recipe.split.fractions)
    nulls = apportion(recipe.pairs.null_states, recipe.split.fractions)
    for split, quota, null in zip(SPLITS, quotas, nulls):
        for k, name in enumerate(("random", "policy")):
            rows = [i for i, (s, src) in enumerate(zip(cols["split"], cols["source"]))
                    if s == split and src == name]
            for c in recipe.commands:
                n = sum(cols["kind"][i] == "matched" and cols["label"][i] == c.id for i in rows)
                assert n == apportion(quota, [0.25, 0.75])[k], (split, name, c.id)
            assert sum(cols["kind"][i] == "null" for i in rows) == \
                apportion(null, [0.25, 0.75])[k]
    # Mismatches are never secretly true, in either source.
    fires = {("random", int(e), int(s)): f for e, s, f in zip(a.episode, a.step, a.fires)}
    fires |= {("policy", int(e), int(s)): f for e, s, f in zip(b.episode, b.step, b.fires)}
    ids = [c.id for c in recipe.commands]
    for src, e, s, cid, kind in zip(cols["source"], cols["episode"], cols["step"],
                                    cols["command_id"], cols["kind"]):
        assert (kind == "matched") == bool(fires[src, e, s][ids.index(cid)])
    # Packing reads each stack from its own source.
    table = packed_rows(recipe, pairs, tmp_path, [_Stub(), _Stub()], ("random", "policy"))
    assert len(table) == len(pairs)
    assert not pairs.equals(build_pairs(mixed(random=0.5, policy=0.5), [a, b]))


def test_a_short_source_is_named_with_the_episodes_it_needs() -> None:
    recipe = mixed(random=0.5, policy=0.5)
    never = labelled(seed=2)
    never.fires[:, 2] = False
    with pytest.raises(NotEnoughStates, match=r"sources: policy: build_supply_depot 0 of 2 "
                                              r"the recipe asks for") as e:
        build_pairs(recipe, [labelled(seed=1), never])
    assert "random:" not in str(e.value) and "policy can never fill it" in str(e.value)
    big = parse(smoke(sources={"random": {"share": 0.5}, "policy": {"share": 0.5}},
                      pairs={"states_per_command": 60, "null_states": 30}))
    with pytest.raises(NotEnoughStates, match=r"grow random to \d+ episodes"):
        build_pairs(big, [labelled(seed=1), labelled(seed=2)])
    few = Labelled(never.episode[:80], never.step[:80], never.fires[:80])  # 2 episodes
    with pytest.raises(NotEnoughStates, match="source policy: an episode-disjoint split needs "
                                              "at least 3 episodes"):
        build_pairs(recipe, [labelled(seed=1), few])


@pytest.mark.parametrize("sources,message", [
    ({"a": {"share": 1.0}}, "one source needs no [sources] table"),
    ({"a": {"share": 0.5}, "b": {"share": 0.6}}, "the shares must sum to 1"),
    ({"a": {"share": 0.5}, "b": {"share": 0.5, "layers": "full"}}, "the same layers"),
    ({"a": {"share": 0.5}, "b": {"share": 0.5, "seed": 3}}, "unknown key 'seed'"),
    ({"a": {"share": 0.5}, "b": {"agent": "scripted"}}, "missing required key 'share'"),
    ({"a": {"share": 0.5}, "../b": {"share": 0.5}}, "names the source's folder"),
    ({"a": {"share": -1}, "b": {"share": 2}}, "share must be positive"),
])
def test_bad_sources_are_recipe_errors(sources: dict[str, Any], message: str) -> None:
    with pytest.raises(RecipeError, match=None) as e:
        parse(smoke(sources=sources))
    assert message in str(e.value)


# -- through the CLI, on simulator data ---------------------------------------------------------
MIXED = """
name = "mixed"
seed = 0

[rollout]
env = "sim"
agent = "reduced-random"
episodes = 3
layers = "paper"

[sources.random]
share = 0.5

[sources.scripted]
share = 0.5
agent = "scripted"

[commands.build_scv]
text = "build an SCV"

[commands.collect_minerals]
text = "collect minerals"

[pairs]
states_per_command = STATES
null_states = 12

[split]
method = "episode"
train = 0.6
val = 0.2
test = 0.2
"""


def recipe_file(folder: Path, states: int = 4, text: str = MIXED) -> Path:
    path = folder / "mixed.toml"
    path.write_text(text.replace("STATES", str(states)))
    return path


@pytest.fixture(scope="module")
def sources(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """DIR/random (reduced-random) and DIR/scripted: 3 labelled episodes of 500 steps each."""
    from tests.cli import exit_code

    root = tmp_path_factory.mktemp("sources")
    for name, agent in (("random", "reduced-random"), ("scripted", "scripted")):
        assert exit_code("rollout", "--agent", agent, "--episodes", "3", "--max-steps", "500",
                         "--episodes-per-shard", "2", "--out", root / name,
                         "--no-progress") == 0
        assert exit_code("label", root / name, "--no-progress") == 0
    return root


def test_a_mixed_pair_set_draws_from_each_source(sources: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    import pyarrow.parquet as pq

    from sc2data.data.dataset import open_dataset
    from sc2data.pairs.packed import PackedSplit
    from tests.cli import run_cli

    recipe = recipe_file(tmp_path)
    out = tmp_path / "pairs"
    code, text, err = run_cli(["pair", recipe, "--data", sources, "--out", out,
                               "--no-progress"], capsys)
    assert code == 0, err
    pairs = pq.read_table(out / "pairs.parquet").to_pydict()
    assert set(pairs["source"]) == {"random", "scripted"}
    for name in ("random", "scripted"):
        sides = [{e for e, s, src in zip(pairs["episode"], pairs["split"], pairs["source"])
                  if s == split and src == name} for split in SPLITS]
        assert all(sides) and len(set().union(*sides)) == sum(map(len, sides)), name
    datasets = {n: open_dataset(sources / n) for n in ("random", "scripted")}
    for split in SPLITS:
        with PackedSplit(out / "packed" / f"{split}.h5") as packed:
            for i in [i for i, s in enumerate(pairs["split"]) if s == split][:6]:
                got = packed.read(pairs["state"][i], pairs["state"][i] + 1)
                want = datasets[pairs["source"][i]].stack(pairs["episode"][i], pairs["step"][i])
                for key in want.schema.keys():
                    np.testing.assert_array_equal(got.arrays[key], want.arrays[key])
    meta = json.loads((out / "pairset.json").read_text())
    assert [s["name"] for s in meta["data"]["sources"]] == ["random", "scripted"]
    assert set(meta["identity"]["labels"]) == {"random", "scripted"}  # covers every source
    code, text, err = run_cli(["info", out], capsys)
    assert code == 0 and "sources" in text and "50.0%" in text and "scripted" in text, err
    code, text, err = run_cli(["pair", recipe, "--data", sources, "--out", out,
                               "--no-progress"], capsys)
    assert code == 0 and "up to date" in text, err


def damage(folder: Path) -> None:
    shard = sorted(folder.glob("shard-*.h5"))[0]
    data = bytearray(shard.read_bytes())
    data[len(data) // 2] ^= 0xFF
    shard.write_bytes(bytes(data))


def test_bad_sources_are_one_line_before_anything_is_written(
        sources: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    from tests.cli import assert_one_line_error, exit_code, run_cli

    def refused(data: Path, recipe: Path, *needles: str) -> None:
        code, _, err = run_cli(["pair", recipe, "--data", data, "--out", tmp_path / "p",
                                "--no-progress"], capsys)
        assert_one_line_error(code, err, *needles)
        assert not (tmp_path / "p").exists() and not list(tmp_path.glob(".p*"))

    data = tmp_path / "data"
    data.mkdir()
    shutil.copytree(sources / "random", data / "random")
    refused(data, recipe_file(tmp_path), "source scripted: ", "does not exist",
            "sc2data rollout --agent scripted")
    shutil.copytree(sources / "scripted", data / "scripted")
    damage(data / "scripted")
    refused(data, recipe_file(tmp_path), "source scripted: ", "damaged or replaced")
    shutil.rmtree(data / "scripted")
    assert exit_code("rollout", "--agent", "scripted", "--episodes", "3", "--max-steps", "20",
                     "--layers", "full", "--out", data / "scripted", "--no-progress") == 0
    assert exit_code("label", data / "scripted", "--no-progress") == 0
    refused(data, recipe_file(tmp_path), "source scripted: ", "layers 'full' (recipe: 'paper')")
    refused(sources, recipe_file(tmp_path, states=500), "too few labelled states for the "
            "recipe's sources", "random: build_scv", "grow random to")
