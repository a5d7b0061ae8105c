"""``sc2data rl record``: a run kept without its model, compared and plotted as the run, refused
in one line by whatever needs the model."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sc2data.rl import runs
from tests.cli import assert_one_line_error, run_cli
from tests.rl.test_cli import TINY
from tests.rl.test_compare import _grid, fake_run


def _record(run: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> Path:
    code, text, err = run_cli(["rl", "record", run, "--out", out], capsys)
    assert code == 0, err
    assert f"recorded {run}" in text
    return out


def test_records_compare_as_their_runs(tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    grid = _grid(tmp_path / "runs")
    records = [_record(r, tmp_path / "records" / r.name, capsys) for r in grid]
    for r, rec in zip(grid, records):
        assert sorted(p.name for p in rec.iterdir()) == ["config.json", "curve.csv",
                                                         "eval.json", "record.json"]
        entry = json.loads((rec / "record.json").read_text())
        assert entry["from_run"] == str(r) and entry["timesteps"] == 400
        assert entry["recorded_by"].startswith("sc2data ")
    figures = {}
    for name, folders in (("runs", grid), ("records", records),
                          ("mixed", [*records[:2], *grid[2:]])):
        out = tmp_path / f"cmp-{name}"
        code, text, err = run_cli(["rl", "compare", *folders, "--reps", "200", "--out", out],
                                  capsys)
        assert code == 0, err
        record = json.loads((out / "compare.json").read_text())
        figures[name] = (record["groups"], record["improvement"], record["curves"])
    strip = {g: {k: v for k, v in d.items() if k != "runs"}
             for g, d in figures["runs"][0].items()}
    for name in ("records", "mixed"):
        assert {g: {k: v for k, v in d.items() if k != "runs"}
                for g, d in figures[name][0].items()} == strip
        assert figures[name][1:] == figures["runs"][1:]
    png = tmp_path / "curves.png"
    code, _, err = run_cli(["rl", "plot", *records, "--group", "--window", "2", "--out", png],
                           capsys)
    assert code == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_trained_run_records_its_model_digest_and_the_record_replaces_itself(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    code, _, err = run_cli(["rl", "train", "--out", run, "--seed", "1", *TINY], capsys)
    assert code == 0, err
    rec = tmp_path / "rec"
    # not evaluated yet: one line, nothing written
    code, _, err = run_cli(["rl", "record", run, "--out", rec], capsys)
    assert_one_line_error(code, err, "no evaluation", "sc2data rl evaluate")
    assert not rec.exists()
    code, _, err = run_cli(["rl", "evaluate", run, "--episodes", "2", "--processes", "1",
                            "--no-progress"], capsys)
    assert code == 0, err
    _record(run, rec, capsys)
    state = json.loads((run / "state.json").read_text())
    entry = json.loads((rec / "record.json").read_text())
    assert entry["model_sha256"] == state["model_sha256"] == runs.sha256_file(run / "model.zip")
    assert (entry["timesteps"], entry["episodes"]) == (state["timesteps"], state["episodes"])
    assert (rec / "eval.json").read_bytes() == (run / "eval.json").read_bytes()
    assert not (rec / "model.zip").exists()
    # trained on and evaluated again: recording into the same folder replaces the record
    more = [a if a != "96" else "160" for a in TINY]
    assert run_cli(["rl", "train", "--out", run, "--seed", "1", *more], capsys)[0] == 0
    assert run_cli(["rl", "evaluate", run, "--episodes", "2", "--processes", "1",
                    "--no-progress"], capsys)[0] == 0
    _record(run, rec, capsys)
    assert json.loads((rec / "record.json").read_text())["timesteps"] == 160
    assert sorted(p.name for p in rec.parent.iterdir()) == ["rec", "run"]  # nothing left over
    code, text, err = run_cli(["rl", "compare", rec, "--reps", "50"], capsys)
    assert code == 0, err
    assert "macro, sparse: 1 run" in text
    # what needs the model refuses the record in one line
    for args in (["rl", "evaluate", rec], ["rl", "train", "--out", rec, "--seed", "1", *more],
                 ["rl", "train", "--out", tmp_path / "new", "--init-policy", rec, *TINY],
                 ["rl", "fork", rec, "--out", tmp_path / "fork", "--mem", rec],
                 ["rl", "record", rec, "--out", tmp_path / "again"]):
        code, _, err = run_cli(args, capsys)
        assert_one_line_error(code, err, "record")
    assert not (tmp_path / "new").exists() and not (tmp_path / "fork").exists()


def test_bad_records_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = fake_run(tmp_path / "run", [1, 2], action_space="paper")
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    code, _, err = run_cli(["rl", "record", run, "--out", other], capsys)
    assert_one_line_error(code, err, "not a run's record", "another --out")
    assert sorted(p.name for p in other.iterdir()) == ["notes.txt"]
    code, _, err = run_cli(["rl", "record", run, "--out", run], capsys)
    assert_one_line_error(code, err, "not a run's record")
    code, _, err = run_cli(["rl", "record", tmp_path / "nothing", "--out", tmp_path / "r"],
                           capsys)
    assert_one_line_error(code, err, "not a trained sc2data rl run")
    rec = _record(run, tmp_path / "rec", capsys)
    for name, edit in (("curve.csv", b"episode\n"), ("eval.json", b"{}")):
        damaged = tmp_path / f"damaged-{name}"
        _record(run, damaged, capsys)
        (damaged / name).write_bytes(edit)
        for args in (["rl", "compare", damaged], ["rl", "plot", damaged, "--out",
                                                   tmp_path / "p.png"]):
            code, _, err = run_cli(args, capsys)
            assert_one_line_error(code, err, "changed or damaged", "record")
    (rec / "record.json").unlink()  # a half-written record: not a run, not a record
    code, _, err = run_cli(["rl", "compare", rec], capsys)
    assert_one_line_error(code, err, "not a trained sc2data rl run")
