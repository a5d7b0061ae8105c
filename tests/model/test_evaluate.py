"""Evaluation: metrics by hand, the report of a real run, t-SNE, and the CLI's errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import sc2data.model.evaluate as ev  # noqa: E402
from sc2data import load_model  # noqa: E402
from sc2data.model.evaluate import accuracy, auc, evaluate, roc_auc  # noqa: E402
from sc2data.pairs.loader import PairSet  # noqa: E402
from tests.cli import assert_one_line_error, run_cli  # noqa: E402
from tests.mem_helpers import tiny_pairset, train_tiny  # noqa: E402


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("eval")
    data = tiny_pairset(root / "data")
    return train_tiny(data, root / "run", epochs=2, lr=2e-3)


def test_accuracy_by_hand() -> None:
    d = np.array([0.1, 0.6, 0.49, 0.5, 0.9, 0.2])
    y = np.array([0, 0, 1, 1, 1, 0], np.float32)
    # predicted match (d < 0.5): T F T F F T; true match (y = 0): T T F F F T → 4 of 6 agree
    assert accuracy(d, y) == pytest.approx(4 / 6)
    assert accuracy(d, y, threshold=0.95) == pytest.approx(3 / 6)


def test_rank_auc_by_hand_and_against_scikit_learn() -> None:
    # positives 0.9, 0.8 against negatives 0.8, 0.1: 1 + 1 + ½ (tie) + 1 = 3.5 of 4
    assert roc_auc(np.array([0.9, 0.8, 0.8, 0.1]), np.array([1, 0, 1, 0])) == 0.875
    assert roc_auc(np.array([1.0, 2.0]), np.array([1, 0])) == 0.0
    assert np.isnan(roc_auc(np.array([1.0, 2.0]), np.array([1, 1])))
    rng = np.random.default_rng(0)
    score = rng.integers(0, 20, 500).astype(float)  # many ties
    positive = rng.random(500) < 0.4
    from sklearn.metrics import roc_auc_score

    assert roc_auc(score, positive) == pytest.approx(roc_auc_score(positive, score), abs=1e-12)
    assert auc(score, positive) == pytest.approx(roc_auc(score, positive), abs=1e-12)


def test_evaluate_on_fixed_distances_matches_a_hand_count(
        run: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every state at a chosen distance from every text: the report must count exactly."""
    config = json.loads((run / "config.json").read_text())
    pairs = PairSet(config["data"])
    rng = np.random.default_rng(1)
    chosen = {s: rng.random(int(pairs.pairs(s).state.max()) + 1) for s in ("train", "val", "test")}
    monkeypatch.setattr(ev, "_embed_split", lambda scorer, data, split, progress=None: np.pad(
        chosen[split][:, None], ((0, 0), (0, 255))).astype(np.float32))
    monkeypatch.setattr(ev.MEMScorer, "embed_texts",
                        lambda self, texts: np.zeros((len(texts), 256), np.float32))
    report = evaluate(run, device="cpu")
    for split in ("train", "val", "test"):
        p = pairs.pairs(split)
        d = chosen[split][p.state]
        hand = sum((di < 0.5) == (yi == 0) for di, yi in zip(d, p.target)) / len(p)
        assert report["splits"][split]["accuracy"] == pytest.approx(hand)
        m = p.kind == "null"
        assert report["splits"][split]["per_kind"]["null"]["accuracy"] == pytest.approx(
            np.mean(d[m] >= 0.5))
        # retrieval: every command is at the state's distance, so argmin is the first command
        states, first = np.unique(p.state, return_index=True)
        truth = np.where(p.label[first] == "", "none", p.label[first])
        first_id = pairs.commands[0]["id"]
        pred = np.where(chosen[split][states] < 0.5, first_id, "none")
        assert report["splits"][split]["retrieval"]["accuracy"] == pytest.approx(
            np.mean(pred == truth))


def test_report_of_a_real_run(run: Path) -> None:
    report = evaluate(run, device="cpu")
    assert json.loads((run / "eval.json").read_text())["splits"]["test"]["pairs"] == \
        report["splits"]["test"]["pairs"]
    config = json.loads((run / "config.json").read_text())
    data = PairSet(config["data"])
    test = report["splits"]["test"]
    p = data.pairs("test")
    assert sum(v["pairs"] for v in test["per_kind"].values()) == len(p)
    assert set(test["per_command"]) == {c["id"] for c in data.commands}
    # the accuracy equals the one recomputed through load_model, pair by pair
    scorer = load_model(run)
    with data.packed("test") as packed:
        stacks = packed.read(0, len(packed))
    d = scorer.distance({k: v[p.state] for k, v in stacks.arrays.items()}, list(p.command))
    assert test["accuracy"] == pytest.approx(accuracy(d, p.target))
    assert test["retrieval"]["states"] == len(np.unique(p.state))
    held = test["phrasings"]["held_out"]
    assert set(held["per_phrase"]) == {t for c in data.commands for t in c["paraphrases"]}
    scores = {t: v["balanced_accuracy"] for t, v in held["per_phrase"].items()}
    assert held["worst"]["balanced_accuracy"] == min(scores.values())
    assert held["mean_balanced_accuracy"] == pytest.approx(np.mean(list(scores.values())))
    assert report["same_data_as_training"]


def test_cli_evaluate_prints_the_table_beside_the_papers(run: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    code, out, err = run_cli(["evaluate", str(run), "--device", "cpu"], capsys)
    assert code == 0, err
    lines = out.splitlines()
    assert lines[0].split()[:4] == ["split", "pairs", "accuracy", "%"]
    assert "95.61" in lines[1] and "82.35" in lines[2] and "80.40" in lines[3]
    assert "held-out paraphrases: mean" in out and f"wrote {run / 'eval.json'}" in out


def test_cli_tsne_writes_a_png(run: Path, tmp_path: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "map.png"
    code, out, err = run_cli(["tsne", str(run), "--out", str(png), "--states", "60",
                              "--text", "make a depot now", "--device", "cpu"], capsys)
    assert code == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    code, _, err = run_cli(["tsne", str(run), "--out", str(png), "--text", "qqzx vvkw"], capsys)
    assert_one_line_error(code, err, "'qqzx vvkw'", "no word")


def test_cli_errors_for_missing_run_foreign_schema_and_bad_data(
        run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["evaluate", str(tmp_path / "nope")], capsys)
    assert_one_line_error(code, err, "run folder", "does not exist")
    (tmp_path / "empty").mkdir()
    code, _, err = run_cli(["evaluate", str(tmp_path / "empty")], capsys)
    assert_one_line_error(code, err, "has no state.json")
    import shutil

    other = tmp_path / "other"
    shutil.copytree(run, other)
    blob = torch.load(other / "best.pt", weights_only=True)
    blob["schema"]["version"] = 99
    torch.save(blob, other / "best.pt")
    code, _, err = run_cli(["evaluate", str(other)], capsys)
    assert_one_line_error(code, err, "best.pt is missing, damaged or was replaced")
    import json

    from sc2data.ground.files import sha256_file

    state = json.loads((other / "state.json").read_text())  # as if trained so
    state["sha256"]["best.pt"] = sha256_file(other / "best.pt")
    (other / "state.json").write_text(json.dumps(state))
    code, _, err = run_cli(["evaluate", str(other)], capsys)
    assert_one_line_error(code, err, "schema version 99")
    code, _, err = run_cli(["evaluate", str(run), "--data", str(tmp_path)], capsys)
    assert_one_line_error(code, err, "pairset.json")


def test_evaluate_refuses_another_pair_set_unless_asked(run: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """A pair set re-drawn from the same episodes mixes splits: refused, never over eval.json."""
    other = tiny_pairset(tmp_path / "other", seed=7)
    before = (run / "eval.json").read_bytes() if (run / "eval.json").exists() else None
    code, _, err = run_cli(["evaluate", str(run), "--data", str(other)], capsys)
    assert_one_line_error(code, err, "is not the pair set", "--other-data")
    code, out, err = run_cli(["evaluate", str(run), "--data", str(other), "--other-data"], capsys)
    assert code == 0, err
    written = [p for p in run.glob("eval-*.json")]
    assert len(written) == 1 and f"wrote {written[0]}" in out
    after = (run / "eval.json").read_bytes() if (run / "eval.json").exists() else None
    assert after == before


def test_tsne_says_when_a_model_has_separated_nothing() -> None:
    from sc2data.model.evaluate import separation_note

    ids = ["a", "b", "c"]
    commands = np.eye(3, dtype=np.float32)
    labels = np.array(["a", "b", "c", "", "a", "b"])
    apart = commands[[0, 1, 2, 0, 0, 1]] + 0.01  # each state at its own command
    assert separation_note(apart, labels, commands, ids) is None
    mixed = commands[[1, 2, 0, 0, 1, 2]]  # every command state at another command
    note = separation_note(mixed, labels, commands, ids)
    assert note is not None and "has not separated" in note and "0% of" in note
    assert "chance 33%" in note
    assert separation_note(mixed, np.array([""] * 6), commands, ids) is None  # null states only


@pytest.mark.parametrize("command", ["train", "evaluate", "tsne"])
def test_long_model_commands_write_progress_lines_to_a_log_file(
        run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch, command: str) -> None:
    """With stderr in a file (capsys: not a terminal), train, evaluate and tsne write whole
    progress lines once their work lasts — never a carriage-return bar."""
    from sc2data.ground import progress

    monkeypatch.setattr(progress, "LOG_EVERY_S", 0.0)
    data = json.loads((run / "config.json").read_text())["data"]
    argv = {"train": ["train", data, "--out", str(tmp_path / "r"), "--epochs", "1",
                      "--vocab-size", "2000", "--threads", "1"],
            "evaluate": ["evaluate", str(run)],
            "tsne": ["tsne", str(run), "--out", str(tmp_path / "t.png"), "--states", "30"]}
    code, out, err = run_cli(argv[command], capsys)
    assert code == 0, err
    desc = "epoch 1/1:" if command == "train" else "embed "
    lines = [line for line in err.splitlines() if line.startswith(desc)]
    assert lines and "\r" not in err, err
    if command == "train":
        assert "epoch   1  train loss" in out  # the epoch's summary line, in the log too
        # short work at the real interval: no bar line at all
        monkeypatch.setattr(progress, "LOG_EVERY_S", 60.0)
        code, out, err = run_cli([*argv[command][:3], str(tmp_path / "r1"), *argv[command][4:]],
                                 capsys)
        assert code == 0 and "epoch 1/1:" not in err and "epoch   1  train loss" in out, err
    code, out, err = run_cli([*argv[command], "--no-progress"] if command != "train" else
                             [*argv[command][:3], str(tmp_path / "r2"), *argv[command][4:],
                              "--no-progress"], capsys)
    assert code == 0 and not err.strip(), err
