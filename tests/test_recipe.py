"""Recipe parsing: the shipped manifests load; malformed ones fail naming the field."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest

from sc2data.ground.recipe import Recipe, RecipeError, load, parse

MANIFESTS = Path(__file__).resolve().parents[1] / "manifests"

BASE: dict[str, Any] = {
    "name": "t", "seed": 3,
    "rollout": {"env": "sim", "agent": "reduced-random", "episodes": 4},
    "commands": {"build_scv": {"text": "build an SCV", "paraphrases": ["make a worker"]},
                 "train_marine": {"text": "train a marine"}},
    "pairs": {"states_per_command": 10, "null_states": 5},
    "split": {"method": "episode", "train": 0.5, "val": 0.25, "test": 0.25},
}


def with_(path: str, value: Any) -> dict[str, Any]:
    """BASE with one dotted key replaced (or deleted when value is ...)."""
    d = copy.deepcopy(BASE)
    *heads, last = path.split(".")
    t = d
    for h in heads:
        t = t[h]
    if value is ...:
        del t[last]
    else:
        t[last] = value
    return d


@pytest.mark.parametrize("path", sorted(MANIFESTS.glob("*.toml")), ids=lambda p: p.name)
def test_shipped_manifests_load(path: Path) -> None:
    recipe = load(path)
    assert isinstance(recipe, Recipe)
    assert len(recipe.commands) >= 2


def test_parse_reads_every_field() -> None:
    r = parse(BASE)
    assert r.seed == 3 and r.rollout.episodes == 4
    assert r.commands[0].paraphrases == ("make a worker",)
    assert r.split.fractions == pytest.approx((0.5, 0.25, 0.25))
    assert r.to_dict()["pairs"]["null_states"] == 5


@pytest.mark.parametrize("path,value,message", [
    ("colour", "red", "unknown key 'colour'"),
    ("rollout.episodes", "ten", "[rollout].episodes must be int"),
    ("rollout.episodes", 0, "[rollout].episodes must be a positive integer"),
    ("rollout.episodes", True, "[rollout].episodes must be int"),
    ("rollout.env", "sc3", "[rollout].env must be one of sim, sc2"),
    ("rollout.layers", "most", "[rollout].layers must be one of paper, full"),
    ("pairs.states_per_command", -5, "[pairs].states_per_command must be a positive integer"),
    ("pairs.null_states", -1, "[pairs].null_states must be a non-negative integer"),
    ("pairs.mismatch", "nearest", "[pairs].mismatch must be one of uniform, confusable"),
    ("pairs.confusable", {"build_scv": ["train_marine"]},
     "[pairs.confusable] and confusable_share apply only with mismatch = \"confusable\""),
    ("pairs", {"states_per_command": 10, "null_states": 5, "mismatch": "confusable"},
     "mismatch = \"confusable\" needs a [pairs.confusable] table"),
    ("pairs", {"states_per_command": 10, "null_states": 5, "mismatch": "confusable",
               "confusable": {"build_depot": ["build_scv"]}},
     "[pairs.confusable]: 'build_depot' is not a command of this recipe"),
    ("pairs", {"states_per_command": 10, "null_states": 5, "mismatch": "confusable",
               "confusable": {"build_scv": ["build_scv"]}},
     "[pairs.confusable].build_scv must be a non-empty list of the recipe's other command ids"),
    ("pairs", {"states_per_command": 10, "null_states": 5, "mismatch": "confusable",
               "confusable": {"build_scv": ["train_marine"]}, "confusable_share": 1.5},
     "[pairs].confusable_share must be a number in (0, 1]"),
    ("pairs.states_per_command", ..., "missing required key 'states_per_command'"),
    ("split.train", 0.9, "must be positive and sum to 1"),
    ("split.method", "stratified", "[split].method must be one of episode, random"),
    ("commands.build_scv.text", 5, "[commands.build_scv].text must be str"),
    ("commands.build_scv.paraphrases", [""], ".paraphrases must be a list of phrases with at "
     "least one word each; got ''"),
    ("commands.build_scv.train_paraphrases", ["train a worker", "  "],
     ".train_paraphrases must be a list of phrases with at least one word each; got '  '"),
    ("commands.build_scv.train_paraphrases", ["?!"], "got '?!'"),
    ("commands.build_scv.train_paraphrases", "train a worker", ".train_paraphrases must be list"),
    ("commands.build_scv.train_paraphrases", ["Make a worker!"],
     "[commands.build_scv].paraphrases: 'make a worker' is already train_paraphrases "
     "'Make a worker!'; a phrase can be in only one list of one command"),
    ("commands.build_scv.train_paraphrases", ["build an scv"],
     "[commands.build_scv].train_paraphrases: 'build an scv' is already text 'build an SCV'"),
    ("commands.train_marine.paraphrases", ["make a worker"],
     "[commands.train_marine].paraphrases: 'make a worker' is already paraphrases "
     "'make a worker' of build_scv"),
    ("commands", {"build_scv": {"text": "x"}}, "at least two commands"),
    ("seed", ..., "missing required key 'seed'"),
    ("pairs", {"states_per_command": 1, "null_states": 0},
     "[pairs]: these counts leave the val split without pairs"),
])
def test_malformed_recipe_names_the_field(path: str, value: Any, message: str) -> None:
    with pytest.raises(RecipeError, match=None) as e:
        parse(with_(path, value), "r.toml")
    assert message in str(e.value)
    assert str(e.value).startswith("r.toml")
    assert "\n" not in str(e.value)


def test_training_phrasings_are_kept_apart_and_absent_from_an_old_recipes_identity() -> None:
    d = with_("commands.build_scv.train_paraphrases", ["train a worker", "make an scv"])
    r = parse(d)
    assert r.commands[0].train_paraphrases == ("train a worker", "make an scv")
    assert r.commands[0].paraphrases == ("make a worker",)
    assert json.loads(json.dumps(r.to_dict()))["commands"][0]["train_paraphrases"] == [
        "train a worker", "make an scv"]
    # a recipe without the key records exactly what it recorded before the key existed
    old = json.loads(json.dumps(parse(BASE).to_dict()))["commands"]
    assert old == [{"id": "build_scv", "text": "build an SCV", "paraphrases": ["make a worker"]},
                   {"id": "train_marine", "text": "train a marine", "paraphrases": []}]


def test_shipped_recipes_train_on_player_phrasings_and_hold_out_others() -> None:
    for path in MANIFESTS.glob("*.toml"):
        for c in load(path).commands:
            assert len(c.train_paraphrases) >= 3 and len(c.paraphrases) >= 3, (path, c.id)
    scv = load(MANIFESTS / "buildmarines-paper.toml").commands[0]
    assert "train a worker" in scv.train_paraphrases and "make an scv" in scv.train_paraphrases


def test_random_split_apportions_pairs_after_drawing() -> None:
    """One state per command and no null: 4 pairs, too few for a 3-way episode split, enough
    for a random one (2 / 1 / 1)."""
    d = with_("pairs", {"states_per_command": 1, "null_states": 0})
    d["split"]["method"] = "random"
    assert parse(d).pairs.states_per_command == 1


def test_load_reports_bad_toml_and_missing_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("name = \n")
    with pytest.raises(RecipeError, match="not valid TOML"):
        load(bad)
    with pytest.raises(RecipeError, match="cannot read recipe"):
        load(tmp_path / "absent.toml")


def test_confusable_is_recorded_only_where_used() -> None:
    assert "confusable" not in json.loads(json.dumps(parse(BASE).to_dict()))["pairs"]
    d = with_("pairs", {"states_per_command": 10, "null_states": 5, "mismatch": "confusable",
                        "confusable": {"build_scv": ["train_marine"]}})
    pairs = json.loads(json.dumps(parse(d).to_dict()))["pairs"]
    assert pairs["confusable"] == {"build_scv": ["train_marine"]}
    assert pairs["confusable_share"] == 0.5
