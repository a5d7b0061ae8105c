"""EPIC (Gleave et al. 2021) as ``sc2data rl agreement`` computes it, on hand-built rewards."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from sc2data.rl.agreement import canonical, epic_distance, pearson, pearson_distance
from sc2data.rl.envs import MACROS

ALL = (np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1]))
"""Every transition over two states: 0→0, 0→1, 1→0, 1→1."""


def matrix(*rewards: np.ndarray) -> object:
    """``reward(i, j)`` of one or more ``(n, n)`` reward matrices (stacked as columns)."""
    def reward(i: np.ndarray, j: np.ndarray) -> np.ndarray:
        cols = [r[i, j] for r in rewards]
        return cols[0] if len(cols) == 1 else np.stack(cols, axis=1)
    return reward


def test_canonical_reward_by_hand() -> None:
    """R = 1 for 0→1, γ = ½, D_S uniform over both states: row means (½, 0), mean ¼, so
    C(R)(s, s') = R(s, s') + ½·m(s') − m(s) − ⅛ = (−⅜, ⅜, ⅛, −⅛) over 00, 01, 10, 11."""
    r = np.array([[0.0, 1.0], [0.0, 0.0]])
    got = canonical(matrix(r), *ALL, np.array([0, 1]), 0.5)
    np.testing.assert_allclose(got, [-0.375, 0.375, 0.125, -0.125])


def test_epic_of_a_hand_computed_pair() -> None:
    """R_A = 1 for 0→1, R_B = 1 for 1→0 (γ = ½, every transition once): canonical rewards
    (−⅜, ⅜, ⅛, −⅛) and (−⅛, ⅛, ⅜, −⅜), covariance 3/64, variances 5/64: ρ = 0.6 and the EPIC
    distance sqrt((1 − 0.6) / 2) = sqrt(0.2), while the raw rewards correlate at −⅓."""
    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    b = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert pearson(a[ALL], b[ALL]) == pytest.approx(-1 / 3)
    c = canonical(matrix(a, b), *ALL, np.array([0, 1]), 0.5)
    assert pearson(c[:, 0], c[:, 1]) == pytest.approx(0.6)
    assert epic_distance(matrix(a, b), *ALL, np.array([0, 1]), 0.5) == pytest.approx(math.sqrt(0.2))


def test_rewards_equal_up_to_shaping_and_scale_are_at_distance_zero() -> None:
    rng = np.random.default_rng(0)
    n, gamma = 7, 0.99
    a = rng.normal(size=(n, n))
    phi = rng.normal(size=n)
    b = 3.0 * a + gamma * phi[None, :] - phi[:, None]  # potential shaping, positive scale
    s, s2 = rng.integers(0, n, 40), rng.integers(0, n, 40)
    support = np.arange(n)
    assert epic_distance(matrix(a, b), s, s2, support, gamma) == pytest.approx(0.0, abs=1e-6)
    assert pearson_distance(a[s, s2], b[s, s2]) > 0.05  # the shaping hides it from plain ρ
    assert epic_distance(matrix(a, -a), s, s2, support, gamma) == pytest.approx(1.0)
    other = rng.normal(size=(n, n))
    assert 0.2 < epic_distance(matrix(a, other), s, s2, support, gamma) < 1.0


def test_constant_rewards_have_no_correlation() -> None:
    assert pearson(np.ones(5), np.arange(5)) is None
    assert pearson_distance(np.zeros(3), np.zeros(3)) is None


def test_agreement_reports_f1_and_the_rewards_correlation_and_epic(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tests.cli import run_cli
    from tests.mem_helpers import tiny_pairset, train_tiny

    mem = train_tiny(tiny_pairset(tmp_path / "pairs"), tmp_path / "mem", epochs=1)
    run = tmp_path / "run"
    code, _, err = run_cli(["rl", "train", "--out", run, "--steps", "64", "--envs", "1",
                            "--rollout", "32", "--batch-size", "32", "--episode-steps", "40",
                            "--no-progress"], capsys)
    assert code == 0, err
    code, text, err = run_cli(["rl", "agreement", run, "--mem", mem, "--episodes", "2"], capsys)
    assert code == 0, err
    assert "F1" in text and "EPIC distance" in text
    result = json.loads((run / "agreement.json").read_text())
    for c in result["commands"].values():
        p, r = c["precision"], c["recall"]
        if p and r:
            assert c["f1"] == pytest.approx(2 * p * r / (p + r))
        assert c["f1"] == (2 * c["tp"] / (2 * c["tp"] + c["fp"] + c["fn"])
                           if c["tp"] + c["fp"] + c["fn"] else None)
    reward = result["reward"]
    assert reward["epic_transitions"] == result["stacks"] == 80  # two 40-step episodes
    assert reward["epic_support"] == 32 and reward["gamma"] == 0.99
    assert reward["epic"] is None or 0.0 <= reward["epic"] <= 1.0
    assert reward["pearson"] is None or -1.0 <= reward["pearson"] <= 1.0
    for c in result["commands"].values():  # every false match is accounted for
        assert sum(c["false_matches"].values()) >= c["fp"]
        alone_missed = round(c["fired_alone"] * (1 - (c["recall_alone"] or 0)))
        assert sum(c["missed_beside"].values()) >= c["fn"] - alone_missed  # misses beside others
        assert c["fired_alone"] <= c["rule_fired"]
        by = c["by_action"]  # every firing under the action chosen in its step
        assert sum(v["fired"] for v in by.values()) == c["rule_fired"]
        assert sum(v["matched"] for v in by.values()) == c["tp"]
        assert set(by) <= set(MACROS)
        sim = c["sim"]  # on the simulator: both judges against the game's record
        assert 0 <= sim["happened"] <= result["stacks"]
        for key in ("rule_precision", "rule_recall", "mem_precision", "mem_recall"):
            assert sim[key] is None or 0.0 <= sim[key] <= 1.0
    assert "recall, only rule" in text and "against the game" in text
    far = result["text_distances"]  # every two texts, both ways alike
    assert set(far) == set(result["commands"])
    assert all(far[a][b] == far[b][a] > 0 for a in far for b in far[a])


def test_false_matches_by_hand() -> None:
    """Stacks: depot fired (matched depot and barracks), barracks fired (matched depot), null
    (matched barracks), both fired (matched all three)."""
    from sc2data.rl.agreement import false_matches

    ids = ["depot", "barracks", "marine"]
    fired = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 0], [1, 1, 0]], bool)
    matched = np.array([[1, 1, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1]], bool)
    assert false_matches(fired, matched, ids) == {
        "depot": {"barracks": 1},
        "barracks": {"depot": 1, "null": 1},
        "marine": {"depot": 1, "barracks": 1},
    }


def test_what_fired_beside_a_miss_by_hand() -> None:
    """Depot and barracks fired together twice (the MEM matched depot once, barracks never),
    depot alone once (missed), marine with depot once (both matched)."""
    from sc2data.rl.agreement import missed_beside

    ids = ["depot", "barracks", "marine"]
    fired = np.array([[1, 1, 0], [1, 1, 0], [1, 0, 0], [1, 0, 1]], bool)
    matched = np.array([[1, 0, 0], [0, 0, 0], [0, 0, 0], [1, 0, 1]], bool)
    assert missed_beside(fired, matched, ids) == {
        "depot": {"barracks": 1}, "barracks": {"depot": 2}, "marine": {}}


def test_text_distances_and_the_summary_marks_misses_no_stack_could_avoid() -> None:
    """Texts 0.6 and 1.2 from "depot": a stack within 0.5 of both "depot" and "marine" would
    put them within 1.0 of each other, so a depot missed beside a marine is marked."""
    from sc2data.rl.agreement import summary, text_distances

    ids = ["depot", "barracks", "marine"]
    d = text_distances(np.array([[0.0, 0.0], [0.6, 0.0], [0.0, 1.2]]), ids)
    assert d["depot"] == {"barracks": 0.6, "marine": 1.2}
    assert d["barracks"]["marine"] == pytest.approx(math.hypot(0.6, 1.2), abs=1e-4)
    blank = {"rule_fired": 0, "mem_matched": 0, "precision": None, "recall": None}
    result = {"stacks": 4, "episodes": 1, "marines": [0], "threshold": 0.5,
              "null_stacks": 0, "null_unmatched": None, "text_distances": d,
              "commands": {"depot": {**blank, "missed_beside": {"barracks": 2, "marine": 1}},
                           "barracks": blank, "marine": blank}}
    line = next(x for x in summary(result) if x.startswith("depot missed"))
    assert line == ("depot missed where also fired: barracks 2, marine 1 (texts 1.20 apart "
                    "≥ 2 × threshold: no stack matches both)")


def test_recall_where_only_its_rule_fired_by_hand() -> None:
    """Depot fired alone twice (matched once), barracks alone once (missed), both on one stack
    (that one counts for neither); marine never fired."""
    from sc2data.rl.agreement import recall_alone

    fired = np.array([[1, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 0]], bool)
    matched = np.array([[1, 0, 0], [0, 0, 0], [1, 0, 0], [1, 1, 1], [0, 1, 0]], bool)
    n, recall = recall_alone(fired, matched)
    assert n.tolist() == [2, 1, 0]
    assert recall == [0.5, 0.0, None]


def test_judges_against_the_games_record_by_hand() -> None:
    """Happened on stacks 0 and 1; the rule fired on 0 and 2, the MEM matched 0, 1 and 3."""
    from sc2data.rl.agreement import against_record

    happened = np.array([1, 1, 0, 0], bool)
    fired = np.array([1, 0, 1, 0], bool)
    matched = np.array([1, 1, 0, 1], bool)
    assert against_record(fired, matched, happened) == {
        "happened": 2, "rule_precision": 0.5, "rule_recall": 0.5,
        "mem_precision": 2 / 3, "mem_recall": 1.0}
    none = against_record(fired, matched, np.zeros(4, bool))
    assert none["rule_recall"] is None and none["rule_precision"] == 0.0


def test_firings_by_the_action_of_their_step_by_hand() -> None:
    from sc2data.rl.agreement import by_action

    actions = np.array(["build", "gather", "build", "no_op", "build"], dtype=object)
    fired = np.array([1, 1, 1, 0, 0], bool)
    matched = np.array([1, 0, 0, 1, 1], bool)
    assert by_action(fired, matched, actions) == {"build": {"fired": 2, "matched": 1},
                                                  "gather": {"fired": 1, "matched": 0}}
