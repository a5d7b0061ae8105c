"""``sc2data rl compare``: the statistics on hand-built score tables against values computed by
hand, groups of hand-built run folders, and bad input as one line."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sc2data.rl import runs
from sc2data.rl.compare import (
    above,
    curve_scores,
    every_game_ended,
    improvement,
    improvement_intervals,
    iqm,
    iqm_intervals,
    profile_intervals,
    reach,
)
from sc2data.rl.evaluate import PROTOCOL, scores
from sc2data.rl.train import RLConfig, _write_json
from tests.cli import assert_one_line_error, run_cli

SEEDS = [1_000_000, 1_000_001]
SIDES = ["west", "east"]


# -- statistics -------------------------------------------------------------------------------

def test_iqm_trims_a_quarter_of_the_runs_from_each_end() -> None:
    # 10 runs: floor(2.5) = 2 trimmed from each end, the mean of 2..7
    assert iqm(np.arange(10.0)[:, None]) == pytest.approx(4.5)
    # 4 runs: one from each end; an outlier run does not move it
    assert iqm(np.array([[1.0], [2.0], [3.0], [400.0]])) == pytest.approx(2.5)
    # 3 runs: nothing trimmed (floor(0.75) = 0), the mean
    assert iqm(np.array([[0.0], [2.0], [4.0]])) == pytest.approx(2.0)


def test_probability_of_improvement_counts_pairs_and_half_ties() -> None:
    x, y = np.array([[1.0], [2.0], [3.0]]), np.array([[0.0], [2.0], [4.0]])
    # pairs x > y: 1>0, 2>0, 3>0, 3>2 = 4; one tie (2, 2) = 0.5; of 9 pairs
    assert improvement(x, y) == pytest.approx(4.5 / 9)
    assert improvement(y, x) == pytest.approx(4.5 / 9)
    assert improvement(np.array([[5.0], [6.0]]), np.array([[1.0], [2.0]])) == 1.0
    assert improvement(x, x) == 0.5


def test_bootstrap_intervals_hold_the_point_and_are_seeded() -> None:
    tables = {"a": np.array([[1.0], [2.0], [3.0], [4.0]]), "flat": np.full((3, 1), 7.0)}
    found = iqm_intervals(tables, reps=500, seed=1)
    point, lo, hi = found["a"]
    assert point == pytest.approx(2.5) and 1.0 <= lo <= point <= hi <= 4.0 and lo < hi
    assert found["flat"] == (7.0, 7.0, 7.0)  # every resample of equal runs is the same
    assert iqm_intervals(tables, reps=500, seed=1) == found
    p, plo, phi = improvement_intervals({"a>f": (tables["a"], tables["flat"])}, 200)["a>f"]
    assert (p, plo, phi) == (0.0, 0.0, 0.0)


def test_a_groups_interval_does_not_depend_on_the_groups_beside_it() -> None:
    # Each group is drawn from a stream of its own, seeded by the scores: the same runs give the
    # same interval alone, after another group, or named otherwise (one shared stream did not).
    runs = np.array([[19.4], [22.4], [25.3], [24.0], [43.4], [17.2], [7.7], [12.6], [12.5], [18.0]])
    other = runs * 1.1 + 3.0
    alone = iqm_intervals({"sparse": runs}, reps=400, seed=0)["sparse"]
    beside = iqm_intervals({"narration": other, "sparse": runs}, reps=400, seed=0)
    assert beside["sparse"] == alone
    assert iqm_intervals({"renamed": runs}, reps=400, seed=0)["renamed"] == alone
    assert beside["narration"] != alone  # other scores, another stream
    assert iqm_intervals({"sparse": runs}, reps=400, seed=1)["sparse"] != alone
    pair = improvement_intervals({"n > s": (other, runs)}, 300)["n > s"]
    assert improvement_intervals({"s > s": (runs, runs), "n > s": (other, runs)},
                                 300)["n > s"] == pair


def test_profiles_count_the_runs_above_each_threshold() -> None:
    tables = {"a": np.array([[1.0], [5.0], [9.0]]), "flat": np.full((2, 1), 3.0)}
    taus = np.array([0.0, 1.0, 4.0, 9.0])
    point, band = profile_intervals(tables, taus, reps=300, seed=2)
    # strictly above: 1, 5, 9 > 0; 5, 9 > 1 and > 4; none > 9
    assert point["a"].tolist() == pytest.approx([1.0, 2 / 3, 2 / 3, 0.0])
    assert point["flat"].tolist() == [1.0, 1.0, 0.0, 0.0]
    assert band["flat"].tolist() == [[1.0, 1.0, 0.0, 0.0]] * 2  # equal runs: no spread
    lo, hi = band["a"]
    assert (lo <= point["a"]).all() and (point["a"] <= hi).all() and lo[1] < hi[1]
    assert profile_intervals(tables, taus, reps=300, seed=2)[1]["a"].tolist() == band["a"].tolist()


def test_reach_is_the_first_point_at_or_above_the_target() -> None:
    assert reach([10, 20, 30], [1.0, 3.0, 2.0], 3.0) == 20
    assert reach([10, 20, 30], [1.0, 3.0, 2.0], 0.5) == 10
    assert reach([10, 20, 30], [1.0, 3.0, 2.0], 3.5) is None


def test_curve_scores_count_every_game_alike_from_when_each_has_ended_an_episode() -> None:
    # game 0 ends short, poor episodes at 10, 20, 30; game 1 its first, long and rich one at 25:
    # a mean over the run's last episodes would read 1 at 10 and 24, game 0 alone
    curve = (np.array([10.0, 20.0, 25.0, 30.0]), np.array([1.0, 3.0, 9.0, 5.0]),
             np.array([0, 0, 1, 0]))
    assert every_game_ended(curve, 2) == 25.0
    assert every_game_ended(curve, 3) is None  # a third game never ended one
    at = np.array([10.0, 24.0, 25.0, 30.0])
    got = curve_scores(curve, 2, at, window=1)
    assert np.isnan(got[:2]).all() and got[2:].tolist() == [(3 + 9) / 2, (5 + 9) / 2]
    got = curve_scores(curve, 2, at, window=2)  # each game's last two: (1, 3) then (3, 5)
    assert got[2:].tolist() == [(2 + 9) / 2, (4 + 9) / 2]
    one = (curve[0], curve[1], np.zeros(4, int))  # one game: its last episodes, as before
    assert curve_scores(one, 1, np.array([5.0, 20.0, 30.0]), window=2)[1:].tolist() == [2.0, 7.0]


# -- run folders ------------------------------------------------------------------------------

def fake_run(path: Path, sampled: list[int], argmax: list[int] | None = None,
             timesteps: int = 400, seeds: list[int] = SEEDS, evaluated_at: int | None = None,
             inputs: dict[str, str] | None = None, **settings: Any) -> Path:
    """A run folder as sc2data rl train and evaluate leave it, with hand-chosen figures: a
    curve of 4 episodes of 100 decisions, an eval.json of ``sampled``/``argmax`` marines;
    ``inputs``: the digests of what the reward reads, as config.json records them."""
    cfg = RLConfig(out=str(path), **{"envs": 1, **settings})  # one game plays the curve
    path.mkdir(parents=True)
    _write_json(path / "config.json", {**cfg.identity(), **({"inputs": inputs} if inputs else {})})
    (path / "model.zip").write_bytes(b"")
    _write_json(path / "state.json", {"timesteps": timesteps, "env_steps": timesteps * 4,
                                      "episodes": 4, "resumes": 0})
    rows = [{"episode": e + 1, "env": 0, "timesteps": 100 * (e + 1), "env_steps": 400 * (e + 1),
             "marines": float(sum(sampled) / len(sampled)) * e, "game_return": 0.0,
             "return": 0.0} for e in range(4)]
    (path / runs.CURVE_CSV).write_bytes(runs.curve_bytes(rows))
    _write_json(path / "eval.json", {
        "episodes": len(seeds), "seeds": seeds, "sides": SIDES[:len(seeds)],
        "sampled": scores(sampled), "argmax": scores(argmax or sampled),
        "trained_timesteps": timesteps if evaluated_at is None else evaluated_at,
        "trained_env_steps": timesteps * 4, "config": cfg.identity(), "protocol": PROTOCOL})
    return path


def _grid(root: Path) -> list[Path]:
    """Narration runs with final means 1, 2, 3, 4 and sparse runs 0, 2, 4 (paper space)."""
    nar = [fake_run(root / f"nar{s}", [m, m], seed=s, action_space="paper", reward="narration",
                    mem="/unused")
           for s, m in enumerate([1, 2, 3, 4])]
    sparse = [fake_run(root / f"sp{s}", [m - 1, m + 1], seed=s, action_space="paper")
              for s, m in enumerate([0, 2, 4])]
    return nar + sparse


def test_compare_groups_seeds_and_reports_hand_computed_figures(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs = _grid(tmp_path)
    baselines = tmp_path / "ref"
    baselines.mkdir()
    _write_json(baselines / "baselines.json", {
        "episodes": 2, "seeds": SEEDS, "sides": SIDES, "episode_steps": None, "backend": "sim",
        "protocol": PROTOCOL, "agents": {"uniform-paper": {"space": "paper", **scores([13, 15])},
                                         "scripted": {"space": "macro", **scores([110, 120])}}})
    out = tmp_path / "cmp"
    code, text, err = run_cli(["rl", "compare", *runs, "--out", out, "--reps", "300",
                               "--baselines", baselines], capsys)
    assert code == 0, err
    record = json.loads((out / "compare.json").read_text())
    assert (out / "compare.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    groups = record["groups"]
    assert set(groups) == {"paper, narration", "paper, sparse"}
    nar, sparse = groups["paper, narration"], groups["paper, sparse"]
    assert nar["seeds"] == [0, 1, 2, 3] and sparse["sampled"]["scores"] == [0.0, 2.0, 4.0]
    assert nar["sampled"]["iqm"] == pytest.approx(2.5)  # the mean of 2 and 3
    assert sparse["sampled"]["iqm"] == pytest.approx(2.0)
    lo, hi = nar["sampled"]["ci"]
    assert 1.0 <= lo <= 2.5 <= hi <= 4.0
    (p,) = record["improvement"]
    # narration over sparse: 1 beats 0; 2 beats 0 and ties 2; 3 beats 0, 2; 4 beats 0, 2, ties 4
    assert (p["x"], p["y"]) == ("paper, narration", "paper, sparse")
    assert p["p"] == pytest.approx((1 + 1.5 + 2 + 2.5) / 12)
    assert record["reference"]["uniform-paper"]["mean"] == 14.0
    curves = record["curves"]
    assert curves["decisions"][0] == 100 and curves["decisions"][-1] == 400
    assert "P(paper, narration > paper, sparse) = 0.58" in text
    assert "reference uniform-paper (paper): 14.00" in text
    # reach: training curves m·e at 100·(e+1) decisions, one game, window 1, so each run's
    # score is its last episode's: 0, m, 2m, 3m; narration's IQM (m = 2, 3) 0, 2.5, 5, 7.5,
    # sparse's mean (m = 0, 2, 4) 0, 2, 4, 6: narration reaches 6 only at 400; sparse never 7.5
    assert record["curves"]["per"] == "game" and record["curves"]["window"] == 1
    assert [(r["x"], r["target"], r["decisions"], r["of"]) for r in record["reach"]] == \
        [("paper, narration", 6.0, 400, 400)]
    assert "paper, narration reaches paper, sparse's last training IQM (6.00) at 400 of 400 " \
        "decisions (1.00)" in text
    # performance profiles: 101 thresholds from 0 to the best run's 4
    prof = record["profiles"]
    assert prof["tau"][0] == 0.0 and prof["tau"][-1] == 4.0 and len(prof["tau"]) == 101
    assert prof["groups"]["paper, narration"]["fraction"][0] == 1.0  # 1, 2, 3, 4 > 0
    assert prof["groups"]["paper, sparse"]["fraction"][0] == pytest.approx(2 / 3)  # 2, 4 > 0
    assert prof["groups"]["paper, sparse"]["fraction"][-1] == 0.0
    assert above(record, 2.5) == {"paper, narration": (2, 4), "paper, sparse": (1, 3)}
    assert ("runs above the masked uniform policy (14.00), sampled: paper, narration 0 of 4; "
            "paper, sparse 0 of 3") in text
    # --against: only the pairs over that group
    code, text, err = run_cli(["rl", "compare", *runs, "--against", "paper, narration",
                               "--reps", "100"], capsys)
    assert code == 0, err
    assert "P(paper, sparse > paper, narration) = 0.42" in text
    assert "paper, sparse reaches paper, narration's last training IQM (7.50) nowhere in 400 " \
        "decisions" in text


def test_groups_are_told_apart_by_the_settings_that_differ(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a = fake_run(tmp_path / "a", [1, 1], action_space="paper", reward="rules", bonus=0.1)
    b = fake_run(tmp_path / "b", [2, 2], action_space="paper", reward="rules", bonus=0.5)
    c = fake_run(tmp_path / "c", [2, 2], action_space="paper", reward="rules", bonus=0.5,
                 shaping="event")
    d = fake_run(tmp_path / "d", [2, 2], action_space="paper", reward="narration",
                 mem="/unused", shaping="potential")
    code, text, err = run_cli(["rl", "compare", a, b, c, d, "--reps", "50"], capsys)
    assert code == 0, err
    assert "paper, rules [bonus=0.1]: 1 run" in text
    assert "paper, rules [bonus=0.5]: 1 run" in text
    # a shaping other than its reward's default is named (its name is its own: nothing added)
    assert "paper, rules, event: 1 run" in text
    assert "paper, narration, potential: 1 run" in text


def test_runs_pipelined_or_in_lockstep_are_one_group(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--env-groups`` only orders the same decisions' random draws: runs of either are seeds
    of one group; a setting that changes learning still tells groups apart."""
    a = fake_run(tmp_path / "a", [1, 1], action_space="paper", env_groups=1, seed=0)
    b = fake_run(tmp_path / "b", [2, 2], action_space="paper", env_groups=2, seed=1)
    c = fake_run(tmp_path / "c", [2, 2], action_space="paper", env_groups=2, seed=2, epochs=2)
    code, text, err = run_cli(["rl", "compare", a, b, c, "--reps", "50"], capsys)
    assert code == 0, err
    assert "paper, sparse [epochs=4]: 2 runs" in text
    assert "paper, sparse [epochs=2]: 1 run" in text


def test_groups_of_other_inputs_name_the_digests_that_differ(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two MEMs: the label names the MEM and its digest (12 hex digits), not the narration's,
    which both share."""
    same = "ab" * 32
    a = fake_run(tmp_path / "a", [1, 1], action_space="paper", reward="narration", mem="m0",
                 inputs={"mem_sha256": "0" * 64, "narration_sha256": same})
    b = fake_run(tmp_path / "b", [2, 2], action_space="paper", reward="narration", mem="m1",
                 inputs={"mem_sha256": "1" * 64, "narration_sha256": same})
    code, text, err = run_cli(["rl", "compare", a, b, "--reps", "50"], capsys)
    assert code == 0, err
    assert f"paper, narration [inputs.mem_sha256={'0' * 12}, mem=m0]: 1 run" in text
    assert f"paper, narration [inputs.mem_sha256={'1' * 12}, mem=m1]: 1 run" in text
    assert "narration_sha256" not in text


def test_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    paper = fake_run(tmp_path / "paper", [1, 2], action_space="paper")
    macro = fake_run(tmp_path / "macro", [1, 2], action_space="macro")
    other = fake_run(tmp_path / "other", [1, 2, 3], action_space="paper", seed=1,
                     seeds=[*SEEDS, 1_000_002])
    stale = fake_run(tmp_path / "stale", [1, 2], action_space="paper", seed=2, evaluated_at=200)
    unevaluated = fake_run(tmp_path / "noeval", [1, 2], action_space="paper", seed=3)
    (unevaluated / "eval.json").unlink()
    old = fake_run(tmp_path / "old", [1, 2], action_space="paper", seed=4)
    _write_json(old / "eval.json", {"episodes": 2, "seeds": SEEDS, "marines": [1, 2],
                                    "mean": 1.5, "std": 0.5, "deterministic": True})
    ref = tmp_path / "ref"
    ref.mkdir()
    _write_json(ref / "baselines.json", {"episodes": 2, "seeds": SEEDS, "sides": SIDES,
                                         "episode_steps": 40, "protocol": PROTOCOL,
                                         "agents": {}})
    cases = [
        ([paper, macro], ("different action spaces", "one at a time")),
        ([paper, "--against", "paper, zorg"], ("unknown group", "'paper, sparse'")),
        ([paper, tmp_path], ("not a trained sc2data rl run",)),
        ([paper, unevaluated], ("no evaluation", "sc2data rl evaluate")),
        ([paper, old], ("older evaluation protocol",)),
        ([paper, stale], ("200 decisions", "trained 400")),
        ([paper, other], ("other episodes",)),
        ([paper, paper], ("given twice",)),
        ([paper, "--baselines", ref], ("other episodes", "2 of 40 steps")),
        ([paper, "--baselines", tmp_path / "nothing"], ("does not exist",)),
        ([paper, "--reps", "0"], ("--reps",)),
    ]
    for args, needles in cases:
        code, _, err = run_cli(["rl", "compare", *args], capsys)
        assert_one_line_error(code, err, *needles)


def test_runs_written_before_shaping_read_as_event_shaping(tmp_path: Path) -> None:
    from sc2data.rl.train import load_config

    run = fake_run(tmp_path / "old", [1, 2], action_space="paper", reward="rules")
    config = json.loads((run / "config.json").read_text())
    del config["shaping"]
    _write_json(run / "config.json", config)
    assert load_config(run).shaping == "event"


def test_runs_written_before_merged_waits_and_sites_read_as_they_were_trained(
        tmp_path: Path) -> None:
    from sc2data.rl.train import load_config

    run = fake_run(tmp_path / "old", [1, 2], action_space="macro", macro_sites="far")
    assert load_config(run).merge_waits is True  # new runs merge the forced waits
    assert load_config(run).macro_sites == "far"
    config = json.loads((run / "config.json").read_text())
    del config["merge_waits"], config["macro_sites"], config["point_head"]
    _write_json(run / "config.json", config)
    assert load_config(run).merge_waits is False and load_config(run).macro_sites == "random"
    assert load_config(run).point_head == "cell"


def test_shaping_defaults_to_the_experiments_choice_per_reward(tmp_path: Path) -> None:
    """Potential-based for the rules reward (paid per firing it was farmed), per match for
    the narration's; what is asked is kept, and a config records the shaping it ran."""
    assert RLConfig(out="r", reward="rules").shaping == "potential"
    assert RLConfig(out="r", reward="narration").shaping == "event"
    assert RLConfig(out="r").shaping == "event"  # sparse: no bonus to pay
    assert RLConfig(out="r", reward="rules", shaping="event").shaping == "event"
    assert RLConfig(out="r", reward="rules").identity()["shaping"] == "potential"


def test_runs_written_before_the_reward_scale_and_clip_settings_read_as_trained(
        tmp_path: Path) -> None:
    """A run whose config predates ``--reward-scale``, ``--vf-coef`` and ``--max-grad-norm``
    was trained at the game's scale with SB3's 0.5 and 0.5."""
    from sc2data.rl.train import load_config

    run = fake_run(tmp_path / "old", [1, 2], action_space="macro")
    config = json.loads((run / "config.json").read_text())
    for key in ("reward_scale", "vf_coef", "max_grad_norm"):
        config.pop(key, None)
    _write_json(run / "config.json", config)
    cfg = load_config(run)
    assert (cfg.reward_scale, cfg.vf_coef, cfg.max_grad_norm) == (1.0, 0.5, 0.5)
