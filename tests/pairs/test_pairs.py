"""The pair builder: exact counts, honest mismatches, disjoint splits, determinism."""

from __future__ import annotations

import copy
from collections import defaultdict
from typing import Any

import numpy as np
import pytest

from sc2data.ground.recipe import parse
from sc2data.pairs.draw import MARGIN, Labelled, NotEnoughStates, apportion, build_pairs
from tests.test_recipe import BASE

RATES = np.array([0.05, 0.03])  # fire rates of build_scv, train_marine


def labelled(episodes: int = 12, steps: int = 200, seed: int = 0) -> Labelled:
    rng = np.random.default_rng(seed)
    ep = np.repeat(np.arange(episodes), steps)
    st = np.tile(np.arange(steps), episodes).astype(np.int32)
    return Labelled(ep, st, rng.random((episodes * steps, 2)) < RATES)


def recipe(**changes: Any) -> Any:
    d = copy.deepcopy(BASE)
    for k, v in changes.items():
        section, key = k.split("__")
        d[section][key] = v
    return parse(d)


@pytest.mark.parametrize("apportion_in,expected", [
    ((10, (0.5, 0.25, 0.25)), [5, 3, 2]), ((150000, (2 / 3, 1 / 6, 1 / 6)), [100000, 25000, 25000]),
    ((1, (0.6, 0.2, 0.2)), [1, 0, 0]),
])
def test_apportion_is_exact(apportion_in: tuple[int, tuple[float, ...]],
                            expected: list[int]) -> None:
    assert apportion(*apportion_in) == expected


@pytest.mark.parametrize("method", ["episode", "random"])
def test_counts_are_exactly_the_recipes(method: str) -> None:
    r = recipe(split__method=method)
    t = build_pairs(r, labelled()).to_pydict()
    for cid in ("build_scv", "train_marine"):
        matched = [k == "matched" and c == cid for k, c in zip(t["kind"], t["command_id"])]
        assert sum(matched) == 10
    assert t["kind"].count("mismatched") == 20
    assert t["kind"].count("null") == 5
    assert len(t["kind"]) == 45


def test_targets_follow_the_kind() -> None:
    t = build_pairs(recipe(), labelled()).to_pydict()
    for kind, target in zip(t["kind"], t["target"]):
        assert target == (0.0 if kind == "matched" else 1.0)


def test_no_mismatch_is_secretly_true() -> None:
    data = labelled()
    key = {(int(e), int(s)): f for e, s, f in zip(data.episode, data.step, data.fires)}
    ids = ["build_scv", "train_marine"]
    t = build_pairs(recipe(), data).to_pydict()
    for e, s, c, k in zip(t["episode"], t["step"], t["command_id"], t["kind"]):
        satisfied = key[(e, s)][ids.index(c)]
        assert satisfied == (k == "matched")


def test_episode_split_is_disjoint_and_random_split_is_not_required_to_be() -> None:
    t = build_pairs(recipe(), labelled()).to_pydict()
    splits: dict[int, set[str]] = defaultdict(set)
    for e, s in zip(t["episode"], t["split"]):
        splits[e].add(s)
    assert all(len(v) == 1 for v in splits.values())
    assert set(t["split"]) == {"train", "val", "test"}


def test_same_seed_same_pairs_other_seed_other_pairs() -> None:
    data = labelled()
    a = build_pairs(recipe(), data)
    assert a.equals(build_pairs(recipe(), data))
    perm = np.random.default_rng(1).permutation(len(data.episode))  # input order must not matter
    shuffled = Labelled(data.episode[perm], data.step[perm], data.fires[perm])
    assert a.equals(build_pairs(recipe(), shuffled))
    d = copy.deepcopy(BASE)
    d["seed"] = 4
    assert not a.equals(build_pairs(parse(d), data))


def test_too_few_positives_says_how_many_of_the_recipes_total_and_how_much_data() -> None:
    """The shortage names each short command's usable states against the recipe's total (not a
    split's share), and the episodes in all that should meet it: the data scaled by the worst
    need-to-found ratio, with the margin."""
    r = recipe(pairs__states_per_command=100, split__method="random")
    data = labelled()
    with pytest.raises(NotEnoughStates) as e:
        build_pairs(r, data)
    drawable = data.fires & ~data.fires.all(axis=1)[:, None]
    marines = int(drawable[:, 1].sum())
    assert marines < 100 <= drawable[:, 0].sum()
    episodes = int(np.ceil(12 * 100 / marines * MARGIN))
    assert str(e.value) == (f"too few labelled states for the recipe: train_marine {marines} of "
                            f"100 the recipe asks for (in 12 episodes); roll out {episodes} "
                            f"episodes in all")
    assert e.value.episodes == episodes


@pytest.mark.parametrize("method", ["episode", "random"])
def test_the_episodes_a_shortage_asks_for_are_enough(method: str) -> None:
    r = recipe(pairs__states_per_command=150, pairs__null_states=2000, split__method=method)
    with pytest.raises(NotEnoughStates) as e:
        build_pairs(r, labelled())
    msg = str(e.value)
    assert "of 150 the recipe asks for" in msg and "of 2000" not in msg and "\n" not in msg
    assert e.value.episodes is not None and e.value.episodes > 12
    build_pairs(r, labelled(episodes=e.value.episodes))  # the same yield, that many episodes


def test_a_command_that_never_fires_cannot_be_grown_into() -> None:
    data = labelled()
    data.fires[:, 1] = False
    with pytest.raises(NotEnoughStates) as e:
        build_pairs(recipe(), data)
    assert e.value.episodes is None
    assert str(e.value).endswith("train_marine 0 of 10 the recipe asks for (in 12 episodes); "
                                 "train_marine never fires in the data; check the agent and the "
                                 "rule")


def test_episode_split_needs_three_episodes() -> None:
    with pytest.raises(NotEnoughStates, match="at least 3 episodes") as e:
        build_pairs(recipe(), labelled(episodes=2, steps=2000))
    assert e.value.episodes == 3
    with pytest.raises(NotEnoughStates) as e:
        build_pairs(recipe(pairs__states_per_command=400), labelled(episodes=2, steps=2000))
    assert e.value.episodes is not None and e.value.episodes > 3  # sized by the yield


# --- training phrasings

TRAIN_PHRASES = ["train a worker", "make an scv", "build a worker"]


def phrased(method: str = "episode") -> Any:
    d = copy.deepcopy(BASE)
    d["split"]["method"] = method
    d["commands"]["build_scv"]["train_paraphrases"] = TRAIN_PHRASES
    return parse(d)


@pytest.mark.parametrize("method,digest", [
    ("episode", "17cc0ed631eadd8c44150ffa19f1af5c53afb85882dd1a3d748ac4c975a35798"),
    ("random", "fcc9cd5130ba014777bc9b5efed396c5bf521cd12d822eadc6de608c6e848ce4"),
])
def test_a_recipe_without_training_phrasings_draws_the_pairs_it_always_did(method: str,
                                                                            digest: str) -> None:
    """The digests were computed by the code before training phrasings existed."""
    import hashlib
    import json

    t = build_pairs(recipe(split__method=method), labelled()).to_pydict()
    assert hashlib.sha256(json.dumps(t, sort_keys=True).encode()).hexdigest() == digest


@pytest.mark.parametrize("method", ["episode", "random"])
def test_training_phrasings_change_only_the_train_splits_texts(method: str) -> None:
    plain = build_pairs(recipe(split__method=method), labelled()).to_pydict()
    t = build_pairs(phrased(method), labelled()).to_pydict()
    assert {k: v for k, v in t.items() if k != "command"} == \
        {k: v for k, v in plain.items() if k != "command"}
    drawn: list[str] = []
    for split, cid, text, canon in zip(t["split"], t["command_id"], t["command"],
                                       plain["command"]):
        if split != "train" or cid != "build_scv":
            assert text == canon  # val and test (and a command without phrasings): canonical
        else:
            assert text in ["build an SCV", *TRAIN_PHRASES]
            drawn.append(text)
    assert "make a worker" not in t["command"]  # the held-out paraphrase is never drawn
    assert "build an SCV" in drawn and set(drawn) & set(TRAIN_PHRASES)


def test_training_phrasings_are_drawn_half_canonical_and_deterministically() -> None:
    d = copy.deepcopy(BASE)
    d["pairs"] = {"states_per_command": 400, "null_states": 400}
    d["commands"]["build_scv"]["train_paraphrases"] = TRAIN_PHRASES
    data = labelled(episodes=40, steps=1000)
    t = build_pairs(parse(d), data).to_pydict()
    assert build_pairs(parse(d), data).to_pydict() == t
    texts = [x for s, c, x in zip(t["split"], t["command_id"], t["command"])
             if s == "train" and c == "build_scv"]
    share = texts.count("build an SCV") / len(texts)
    assert 0.45 < share < 0.55, share
    for p in TRAIN_PHRASES:  # the other half, uniformly over the phrasings
        assert abs(texts.count(p) / len(texts) - 0.5 / len(TRAIN_PHRASES)) < 0.05
    d["seed"] = 4
    other = build_pairs(parse(d), data).to_pydict()["command"]
    assert other != t["command"]


# --- confusable mismatches (hard negatives)

THREE = ["build_scv", "train_marine", "build_barracks"]


def three(mismatch: dict[str, Any] | None = None) -> Any:
    d = copy.deepcopy(BASE)
    d["commands"]["build_barracks"] = {"text": "build a barracks"}
    d["pairs"] = {"states_per_command": 60, "null_states": 5, **(mismatch or {})}
    return parse(d)


def labelled3() -> Labelled:
    rng = np.random.default_rng(1)
    ep = np.repeat(np.arange(12), 400)
    st = np.tile(np.arange(400), 12).astype(np.int32)
    return Labelled(ep, st, rng.random((len(ep), 3)) < np.array([0.06, 0.06, 0.06]))


@pytest.mark.parametrize("share, low, high", [(1.0, 1.0, 1.0), (0.5, 0.62, 0.88)])
def test_confusable_mismatches_name_the_listed_command_and_change_nothing_else(
        share: float, low: float, high: float) -> None:
    """A build_scv state's mismatches name train_marine with probability share (else uniformly
    one of the two others: 0.5 + share / 2 in all, 0.75 at ½), unless train_marine fires on it;
    every other column, and every other pair, is the uniform recipe's."""
    data = labelled3()
    key = {(int(e), int(s)): f for e, s, f in zip(data.episode, data.step, data.fires)}
    plain = build_pairs(three(), data).to_pydict()
    t = build_pairs(three({"mismatch": "confusable", "confusable_share": share,
                           "confusable": {"build_scv": ["train_marine"]}}), data).to_pydict()
    assert {k: v for k, v in t.items() if k not in ("command_id", "command")} == \
        {k: v for k, v in plain.items() if k not in ("command_id", "command")}
    named = []
    for i, (kind, label) in enumerate(zip(t["kind"], t["label"])):
        if kind != "mismatched" or label != "build_scv":
            assert t["command_id"][i] == plain["command_id"][i]
            continue
        fires = key[(t["episode"][i], t["step"][i])]
        assert not fires[THREE.index(t["command_id"][i])]  # never secretly true
        if not fires[1]:
            named.append(t["command_id"][i] == "train_marine")
    assert len(named) > 30 and low <= np.mean(named) <= high
    again = build_pairs(three({"mismatch": "confusable", "confusable_share": share,
                               "confusable": {"build_scv": ["train_marine"]}}), data).to_pydict()
    assert again == t  # deterministic


# --- multi_match: a state that satisfies several commands, matched with each

def test_multi_match_adds_a_matched_pair_for_every_other_command_a_drawn_state_satisfies() -> None:
    data = labelled3()
    key = {(int(e), int(s)): f for e, s, f in zip(data.episode, data.step, data.fires)}
    plain = build_pairs(three(), data).to_pylist()
    multi = build_pairs(three({"multi_match": True}), data).to_pylist()
    rows = [tuple(sorted(r.items())) for r in multi]
    extra = list(rows)
    for r in plain:  # every pair of the plain recipe is there, drawn alike
        extra.remove(tuple(sorted(r.items())))
    drawn = {(r["split"], r["episode"], r["step"], r["label"]) for r in plain
             if r["kind"] == "matched"}
    expect = sorted((s, e, st, THREE[c], lab) for s, e, st, lab in drawn
                    for c in np.flatnonzero(key[(e, st)]) if THREE[c] != lab)
    got = sorted((d["split"], d["episode"], d["step"], d["command_id"], d["label"])
                 for d in map(dict, extra))
    assert got == expect and len(got) > 5  # labelled3 has states where two rules fire
    assert all(dict(d)["kind"] == "matched" and dict(d)["target"] == 0.0 for d in extra)
    assert build_pairs(three({"multi_match": True}), data).to_pylist() == multi


def test_multi_match_is_recorded_only_when_set() -> None:
    assert "multi_match" not in three().to_dict()["pairs"]  # older recipes keep their identity
    assert three({"multi_match": True}).to_dict()["pairs"] == {
        "states_per_command": 60, "null_states": 5, "mismatch": "uniform", "multi_match": True}
    hard = {"mismatch": "confusable", "confusable": {"build_scv": ["train_marine"]}}
    assert three({**hard, "multi_match": True}).to_dict()["pairs"] == {
        **three(hard).to_dict()["pairs"], "multi_match": True}
    assert three(hard).to_dict()["pairs"]["confusable"] == {"build_scv": ["train_marine"]}
    with pytest.raises(Exception, match=r"multi_match must be bool"):
        three({"multi_match": "yes"})
