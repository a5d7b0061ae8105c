"""Labelling: output tables and provenance, resume after interruption, and failures that leave
nothing half-written — on hand-built episodes with events at known steps."""

from __future__ import annotations

import re
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from sc2data._pysc2 import units
from sc2data.ground import files
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import PARTIAL, FolderLock
from sc2data.labels.label import PARTS_DIR, label
from sc2data.labels.registry import Registered, RuleError, load_registry, load_rules_dir
from sc2data.labels.source import Source, WorkUnit
from sc2data.labels.store import LABELS_FILE, STACKS_FILE, SUMS_FILE, read_labels, read_meta
from sc2data.rulebase import (
    SCREEN_PX_PER_UNIT,
    blank_frame,
    paint_disk,
    set_field,
    stack,
)
from sc2data.schema import Schema, StackBatch
from tests.cli import assert_one_line_error, exit_code, run_cli

BUILTIN = load_registry()
RULES = list(BUILTIN)
STEPS = 20
EVENTS = {3: "build_scv", 5: "build_supply_depot", 8: "build_barracks", 11: "train_marine",
          14: "collect_minerals"}
"""Step (index of the stack's current frame) → the rule that must fire there, per episode."""


def episode_frames(schema: Schema = Schema.paper()) -> list[dict]:
    """STEPS + 1 frames of one episode, changing at the steps of EVENTS (and 16: both SCV and
    marine at once)."""
    frames, f = [], blank_frame(schema)
    set_field(f, "player", "food_workers", 12)
    set_field(f, "player", "idle_worker_count", 1)
    for step in range(STEPS + 1):
        f = {k: v.copy() for k, v in f.items()}
        if step in (3, 16):  # an SCV is completed: its value appears
            value = int(f["score_cumulative"][3])
            set_field(f, "score_cumulative", "total_value_units", value + 50)
        if step == 5 and "screen/unit_type" in f:
            paint_disk(f, "screen/unit_type", (40, 12), 1.125 * SCREEN_PX_PER_UNIT,
                       int(units.Terran.SupplyDepot))
        if step == 8 and "screen/unit_type" in f:
            paint_disk(f, "screen/unit_type", (40, 30), 1.8125 * SCREEN_PX_PER_UNIT,
                       int(units.Terran.Barracks))
        if step in (11, 16):  # a marine is completed: BuildMarines' score and the value rise
            set_field(f, "score_cumulative", "score", int(f["score_cumulative"][0]) + 1)
            value = int(f["score_cumulative"][3])
            set_field(f, "score_cumulative", "total_value_units", value + 50)
        if step == 14:
            set_field(f, "player", "idle_worker_count", 0)
        frames.append(f)
    return frames


EXPECTED = {(s, r) for s, r in EVENTS.items()} | {(16, "build_scv"), (16, "train_marine")}


def make_unit(episode: int, calls: list | None = None, fail_at: int | None = None,
              schema: Schema = Schema.paper()) -> WorkUnit:
    frames = episode_frames(schema)
    pairs = list(zip(frames[:-1], frames[1:]))

    def batches(batch_size: int, keys: Sequence[str]):  # type: ignore[no-untyped-def]
        if calls is not None:
            calls.append((episode, tuple(keys)))
        for start in range(0, len(pairs), batch_size):
            if fail_at is not None and start >= fail_at:
                raise KeyboardInterrupt
            chunk = stack(pairs[start:start + batch_size], schema)
            batch = StackBatch({k: chunk.arrays[k] for k in keys}, schema)
            steps = np.arange(start + 1, start + 1 + len(batch))
            yield np.full(len(batch), episode), steps, batch

    return WorkUnit(key=f"shard-{episode}", stacks=len(pairs), batches=batches)


def source(n: int = 3, **kw) -> Source:  # type: ignore[no-untyped-def]
    return Source([make_unit(e, **kw) for e in range(n)], Schema.paper(),
                  {"path": "hand-built", "fingerprint": "abc"})


def test_labels_tables_and_provenance(tmp_path: Path) -> None:
    calls: list = []
    summary = label(source(calls=calls), RULES, tmp_path, batch_size=7, progress=False)
    assert {k for _, k in calls} == {("screen/unit_type", "player", "score_cumulative")}

    fired = pq.read_table(tmp_path / LABELS_FILE).to_pylist()
    assert {(r["step"], r["rule_id"]) for r in fired} == EXPECTED
    assert len(fired) == 3 * len(EXPECTED) and [r["episode"] for r in fired[:7]] == [0] * 7
    depot = next(r for r in fired if r["rule_id"] == "build_supply_depot")
    assert depot == {"episode": 0, "step": 5, "rule_id": "build_supply_depot", "rule_version": 1,
                     "command": "build a supply depot"}

    wide = pq.read_table(tmp_path / STACKS_FILE)
    assert wide.column_names == ["episode", "step", *[e.id for e in RULES]]
    assert wide.num_rows == 3 * STEPS
    null = sum(1 for row in wide.to_pylist() if not any(row[e.id] for e in RULES))
    assert null == 3 * (STEPS - 6)

    meta = read_meta(tmp_path)
    assert [r["id"] for r in meta["rules"]] == [e.id for e in RULES]
    assert meta["rules"][0]["source"].startswith("sc2data ") and meta["dataset"]["path"] == \
        "hand-built"
    assert meta["counts"]["build_scv"] == 6 and meta["null"] == null and meta["multi"] == 3
    assert summary.stacks == 60 and summary.counts == meta["counts"]
    assert not (tmp_path / PARTS_DIR).exists()
    labels = read_labels(tmp_path)
    assert labels.fired.num_rows == len(fired) and labels.stacks.num_rows == 60

    table = summary.table()
    assert "build a supply depot" in table and "5.000%" in table
    assert "(null: no rule fired)" in table and "70.000%" in table


def test_rerun_is_up_to_date_and_new_rules_relabel(tmp_path: Path) -> None:
    label(source(), RULES, tmp_path, progress=False)
    calls: list = []
    again = label(source(calls=calls), RULES, tmp_path, progress=False)
    assert again.up_to_date and calls == []
    with pytest.raises(Sc2DataError, match="already has labels of the rules build_scv, "
                                           ".*Pass --overwrite to replace them"):
        label(source(calls=calls), RULES[:2], tmp_path, progress=False)
    assert calls == [] and read_meta(tmp_path)["counts"].keys() == {r.id for r in RULES}
    fewer = label(source(calls=calls), RULES[:2], tmp_path, progress=False, overwrite=True)
    assert not fewer.up_to_date and len(calls) == 3
    assert read_meta(tmp_path)["counts"].keys() == {"build_scv", "collect_minerals"}


def _interrupted(tmp_path: Path) -> tuple[Path, Path]:
    """A reference labelling, and a run of the same rules Ctrl-C'd in its second unit."""
    reference = tmp_path / "ref"
    label(source(), RULES, reference, progress=False)
    out = tmp_path / "out"
    broken = Source([make_unit(0), make_unit(1, fail_at=7), make_unit(2)], Schema.paper(),
                    {"path": "hand-built", "fingerprint": "abc"})
    with pytest.raises(KeyboardInterrupt):
        label(broken, RULES, out, batch_size=7, progress=False)
    return reference, out


def test_resume_after_interruption(tmp_path: Path) -> None:
    reference, out = _interrupted(tmp_path)
    assert not (out / LABELS_FILE).exists() and not (out / STACKS_FILE).exists()
    assert len(list((out / PARTS_DIR).glob("*.parquet"))) == 1
    assert not [p for p in out.rglob("*") if ".tmp" in p.name]

    calls: list = []
    summary = label(source(calls=calls), RULES, out, progress=False)
    assert [e for e, _ in calls] == [1, 2] and summary.resumed_units == 1
    for name in (LABELS_FILE, STACKS_FILE):
        assert pq.read_table(out / name).equals(pq.read_table(reference / name))


def test_stale_parts_of_other_rules_are_discarded(tmp_path: Path) -> None:
    broken = Source([make_unit(0), make_unit(1, fail_at=0)], Schema.paper(), {"fingerprint": "x"})
    with pytest.raises(KeyboardInterrupt):
        label(broken, RULES, tmp_path, progress=False)
    calls: list = []
    label(Source([make_unit(0, calls=calls), make_unit(1, calls=calls)], Schema.paper(),
                 {"fingerprint": "x"}), RULES[:3], tmp_path, progress=False)
    assert [e for e, _ in calls] == [0, 1]


def nothing_written(folder: Path) -> bool:
    return not (folder / LABELS_FILE).exists() and not (folder / STACKS_FILE).exists() and \
        not [p for p in folder.rglob("*") if p.name.endswith(PARTIAL)]


def test_missing_layer_is_named_before_any_work(tmp_path: Path) -> None:
    schema = Schema.from_names(["player_relative"], ["camera"])
    calls: list = []
    src = Source([make_unit(0, calls=calls, schema=schema)], schema, {})
    with pytest.raises(Sc2DataError, match=r"^rule 'build_supply_depot' \(sc2data .*\) needs "
                                           r"'screen/unit_type', which the dataset at .* does not "
                                           r"store; .* --exclude build_supply_depot$"):
        label(src, RULES, tmp_path, progress=False)
    assert calls == [] and nothing_written(tmp_path) and not (tmp_path / PARTS_DIR).exists()
    no_pixels = [e for e in RULES if "screen/unit_type" not in e.rule.requires]
    assert label(src, no_pixels, tmp_path, progress=False).stacks == STEPS


def misbehaving(tmp_path: Path, body: str) -> list[Registered]:
    """A rule that passes load-time validation (small batches) but fails on real, larger ones."""
    folder = tmp_path / "rules"
    folder.mkdir()
    (folder / "late.py").write_text(
        "import numpy as np\nfrom sc2data.rulebase import rule\n"
        "@rule(id='late_bloomer', command='fail late', requires=['player'])\n"
        f"def f(batch):\n    if len(batch) > 5:\n        {body}\n"
        "    return np.zeros(len(batch), bool)\n")
    return load_rules_dir(folder)


@pytest.mark.parametrize("body, message", [
    ("raise ValueError('boom')", r"^rule 'late_bloomer' from file .*late\.py raised ValueError: "
                                 r"boom on the stacks from episode 0 step 1 to episode 0 step 7$"),
    ("return np.zeros(3, bool)", r"^rule 'late_bloomer' .* returned bool array of shape \(3,\) "
                                 r"for 7 stacks \(the stacks from episode 0 step 1 to episode 0 "
                                 r"step 7\); a rule must return a \(7,\) bool array$"),
    ("return np.zeros(len(batch))", r"^rule 'late_bloomer' .* returned float64 array"),
    ("import sys; sys.exit(0)", r"^rule 'late_bloomer' .* called sys.exit\(0\) on the stacks"),
])
def test_rule_failing_on_data_leaves_no_labels(tmp_path: Path, body: str, message: str) -> None:
    out = tmp_path / "data"
    out.mkdir()
    with pytest.raises(RuleError, match=message):
        label(source(), RULES + misbehaving(tmp_path, body), out, batch_size=7, progress=False)
    assert nothing_written(out)


def test_failure_keeps_an_older_complete_labels_file(tmp_path: Path) -> None:
    label(source(), RULES, tmp_path, progress=False)
    before = (tmp_path / LABELS_FILE).read_bytes()
    with pytest.raises(RuleError):
        label(source(), RULES + misbehaving(tmp_path, "raise ValueError('boom')"), tmp_path,
              batch_size=7, progress=False, overwrite=True)
    assert (tmp_path / LABELS_FILE).read_bytes() == before
    assert read_labels(tmp_path).meta["counts"]["build_scv"] == 6


def test_unwritable_folder_and_concurrent_runs(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    with pytest.raises(Sc2DataError, match=r"^cannot write labels in .*a-file/data: "):
        label(source(), RULES, blocker / "data", progress=False)
    monkeypatch.setattr(files, "LOCK_WAIT_S", 0.2)
    with FolderLock(tmp_path, "rollout"):  # the lock's message names the command holding it
        with pytest.raises(Sc2DataError, match="^another sc2data rollout is writing to "):
            label(source(), RULES, tmp_path, progress=False)
    assert nothing_written(tmp_path)


def test_mismatched_files_are_refused(tmp_path: Path) -> None:
    label(source(), RULES, tmp_path / "a", progress=False)
    label(source(), RULES[:2], tmp_path / "b", progress=False)
    (tmp_path / "b" / STACKS_FILE).replace(tmp_path / "a" / STACKS_FILE)
    with pytest.raises(Sc2DataError, match="stack_labels.parquet is damaged or was replaced"):
        read_labels(tmp_path / "a")
    with pytest.raises(Sc2DataError, match="no labels in"):
        read_meta(tmp_path / "c")


def test_bad_batch_size(tmp_path: Path) -> None:
    with pytest.raises(Sc2DataError, match="--batch-size must be at least 1"):
        label(source(), RULES, tmp_path, batch_size=0, progress=False)


# -- the CLI on a real rolled-out dataset ----------------------------------------------------------

@pytest.fixture(scope="module")
def rolled_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small simulator dataset (3 episodes × 150 steps, 2 shards), made as a user makes one."""
    out = tmp_path_factory.mktemp("rollout") / "data"
    assert exit_code("rollout", "--out", str(out), "--episodes", "3", "--max-steps", "150",
                   "--episodes-per-shard", "2", "--seed", "3", "--no-progress") == 0
    return out


@pytest.fixture
def data(rolled_out: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(rolled_out, tmp_path / "data"))




def one_line_error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert err.startswith("sc2data: error: ") and err.count("\n") == 1, err
    return err


def test_cli_label_a_dataset(data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert exit_code("label", str(data), "--no-progress", "--batch-size", "100") == 0
    out = capsys.readouterr().out
    assert "(null: no rule fired)" in out and "450 stacks labelled" in out
    labels = read_labels(data)
    assert labels.stacks.num_rows == 450
    assert labels.stacks.column("step").type == "int32"
    assert sorted(set(labels.stacks.column("episode").to_pylist())) == [0, 1, 2]
    assert labels.meta["dataset"]["stacks"] == 450 and labels.meta["dataset"]["fingerprint"]
    wide = labels.stacks.to_pylist()
    fired = {(r["episode"], r["step"], r["rule_id"]) for r in labels.fired.to_pylist()}
    assert fired == {(r["episode"], r["step"], e.id) for r in wide for e in RULES if r[e.id]}
    assert exit_code("label", str(data), "--no-progress") == 0
    assert "labels are up to date" in capsys.readouterr().out
    assert exit_code("verify", str(data)) == 0  # the dataset is untouched by its labels


def test_labels_after_a_grow_are_a_fresh_runs(data: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """Labelled, grown by an episode (its partial last shard rolled out again), labelled again:
    the labels of a dataset rolled out at that size at once, labels fingerprint included."""
    assert exit_code("label", str(data), "--no-progress") == 0
    assert exit_code("rollout", "--out", str(data), "--episodes", "4", "--no-progress") == 0
    assert exit_code("label", str(data), "--no-progress") == 0
    assert "up to date" not in capsys.readouterr().out
    fresh = tmp_path / "fresh"
    assert exit_code("rollout", "--out", str(fresh), "--episodes", "4", "--max-steps", "150",
                     "--episodes-per-shard", "2", "--seed", "3", "--no-progress") == 0
    assert exit_code("label", str(fresh), "--no-progress") == 0
    grown, again = read_labels(data), read_labels(fresh)
    assert grown.stacks.equals(again.stacks) and grown.fired.equals(again.fired)
    assert grown.stacks.num_rows == 600
    assert grown.meta["fingerprint"] == again.meta["fingerprint"]


def test_cli_label_selects_rules(data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert exit_code("label", str(data), "--no-progress", "--rules", "build_scv,train_marine",
                   "--exclude", "train_marine") == 0
    assert [r["id"] for r in read_meta(data)["rules"]] == ["build_scv"]
    assert exit_code("label", str(data), "--no-progress", "--rules", "build_cc") == 2
    assert "unknown rule id 'build_cc'; known rules: build_scv, collect_minerals" in \
        one_line_error(capsys)


def test_cli_label_refuses_a_folder_that_is_not_a_dataset(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert exit_code("label", str(tmp_path), "--no-progress") == 2
    assert "is not an sc2data dataset" in one_line_error(capsys)
    assert list(tmp_path.iterdir()) == []


BAD_RULE = """
import numpy as np
from sc2data.rulebase import rule

@rule(id="{id}", command="misbehave", requires={requires})
def f(batch):
    {body}
"""


@pytest.mark.parametrize("rule_id, requires, body, message", [
    ("sees_progress", '["screen/build_progress"]', "return np.zeros(len(batch), bool)",
     r"rule 'sees_progress' \(file .*bad\.py\) needs 'screen/build_progress', which the dataset "
     r"at .* does not store"),
    ("late_raiser", '["player"]',
     "if len(batch) > 5:\n        raise RuntimeError('oops')\n"
     "    return np.zeros(len(batch), bool)",
     r"rule 'late_raiser' from file .*bad\.py raised RuntimeError: oops on the stacks from "
     r"episode 0 step 0"),
    ("late_shape", '["player"]',
     "return np.zeros(min(len(batch), 5), bool)",
     r"rule 'late_shape' .* returned bool array of shape \(5,\) for 100 stacks"),
    ("build_scv", '["player"]', "return np.zeros(len(batch), bool)",
     r"rule id 'build_scv' is defined twice: by sc2data .* and by file .*bad\.py"),
])
def test_cli_bad_rules_fail_in_one_line_leaving_nothing(
        data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], rule_id: str,
        requires: str, body: str, message: str) -> None:
    folder = tmp_path / "my_rules"
    folder.mkdir()
    (folder / "bad.py").write_text(BAD_RULE.format(id=rule_id, requires=requires, body=body))
    assert exit_code("label", str(data), "--rules-dir", str(folder), "--no-progress",
                   "--batch-size", "100") == 2
    assert re.search(message, one_line_error(capsys))
    assert nothing_written(data)


def test_cli_label_resumes_after_interruption(data: Path, tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    clean = Path(shutil.copytree(data, tmp_path / "clean"))
    assert exit_code("label", str(clean), "--no-progress") == 0

    from sc2data.data.dataset import Dataset

    read, calls = Dataset.read, []

    def flaky(self, episodes, steps, keys=None):  # type: ignore[no-untyped-def]
        calls.append(int(episodes[0]))
        if int(episodes[0]) == 2:  # the second shard holds episode 2
            raise KeyboardInterrupt
        return read(self, episodes, steps, keys)

    monkeypatch.setattr(Dataset, "read", flaky)
    assert exit_code("label", str(data), "--no-progress") == 130  # Ctrl-C's exit status
    assert nothing_written(data) and len(list((data / PARTS_DIR).glob("*.parquet"))) == 1
    monkeypatch.setattr(Dataset, "read", read)
    assert exit_code("label", str(data), "--no-progress") == 0
    for name in (LABELS_FILE, STACKS_FILE):
        assert pq.read_table(data / name).equals(pq.read_table(clean / name))
    assert not (data / PARTS_DIR).exists()


def test_cli_label_in_worker_processes_equals_one_process(
        data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    one, fresh = (Path(shutil.copytree(data, tmp_path / n)) for n in ("one", "fresh"))
    assert exit_code("label", str(one), "--no-progress") == 0
    assert exit_code("label", str(data), "--no-progress", "--workers", "2") == 0
    for name in (LABELS_FILE, STACKS_FILE):
        a, b = (pq.read_table(d / name) for d in (data, one))
        assert a.replace_schema_metadata(None).equals(b.replace_schema_metadata(None)), name
    assert read_meta(data)["fingerprint"] == read_meta(one)["fingerprint"]
    folder = tmp_path / "my_rules"
    folder.mkdir()
    (folder / "bad.py").write_text(BAD_RULE.format(
        id="late_raiser", requires='["player"]',
        body="if len(batch) > 5:\n        raise RuntimeError('oops')\n"
             "    return np.zeros(len(batch), bool)"))
    capsys.readouterr()
    assert exit_code("label", str(fresh), "--rules-dir", str(folder), "--no-progress",
                     "--workers", "2") == 2
    assert re.search(r"^sc2data: error: label of shard-0000[01]\.h5 failed: rule 'late_raiser' "
                     r"from file .*bad\.py raised RuntimeError: oops", one_line_error(capsys))
    assert nothing_written(fresh)
    assert exit_code("label", str(data), "--no-progress", "--workers", "0") == 2
    assert "workers must be at least 1, not 0" in one_line_error(capsys)


def test_label_unit_reloads_for_a_new_run_in_a_long_lived_process(tmp_path: Path) -> None:
    """A process that labels units of several runs (Ray's workers do) sees each run's data:
    after the dataset at the same path is rolled out anew, a second label run works."""
    from sc2data.labels.label import label_dataset
    from sc2data.labels.remote import label_unit

    data = tmp_path / "data"

    def in_this_process(todo, keys, batch_size, bar):  # type: ignore[no-untyped-def]
        for unit, part in todo:
            label_unit(str(data), (None, (), None), unit.key, str(part), keys, batch_size,
                       bar.update)

    dataset_fingerprints: list[str] = []
    for seed in ("3", "4"):
        shutil.rmtree(data, ignore_errors=True)
        assert exit_code("rollout", "--out", str(data), "--episodes", "2", "--max-steps", "60",
                         "--seed", seed, "--no-progress") == 0
        assert label_dataset(data, progress=False, run_units=in_this_process).stacks == 120
        dataset_fingerprints.append(read_meta(data)["dataset"]["fingerprint"])
    assert dataset_fingerprints[0] != dataset_fingerprints[1]


def _flip(path: Path, at: int) -> None:
    with open(path, "r+b") as f:
        f.seek(at)
        b = f.read(1)
        f.seek(at)
        f.write(bytes([b[0] ^ 0xFF]))


def test_damaged_label_file_is_an_error_and_a_rerun_relabels(tmp_path: Path) -> None:
    """Flipped bytes in stack_labels.parquet: never "up to date", never read as labels."""
    label(source(), RULES, tmp_path, progress=False)
    reference = pq.read_table(tmp_path / STACKS_FILE)
    _flip(tmp_path / STACKS_FILE, 40)
    with pytest.raises(Sc2DataError, match=r"stack_labels.parquet is damaged .*; rerun sc2data "
                                           r"label"):
        read_labels(tmp_path)
    calls: list = []
    again = label(source(calls=calls), RULES, tmp_path, progress=False)
    assert not again.up_to_date and len(calls) == 3
    assert read_labels(tmp_path).stacks.equals(reference)


def test_labels_without_their_checksums_are_refused(tmp_path: Path) -> None:
    label(source(), RULES, tmp_path, progress=False)
    (tmp_path / SUMS_FILE).unlink()
    with pytest.raises(Sc2DataError, match=r"labels.sha256 is missing"):
        read_labels(tmp_path)


def test_a_damaged_part_is_labelled_again_on_resume(tmp_path: Path) -> None:
    reference, out = _interrupted(tmp_path)
    (part,) = (out / PARTS_DIR).glob("*.parquet")
    _flip(part, part.stat().st_size // 2)
    calls: list = []
    summary = label(source(calls=calls), RULES, out, progress=False)
    assert [e for e, _ in calls] == [0, 1, 2] and summary.resumed_units == 0
    assert read_labels(out).stacks.equals(read_labels(reference).stacks)


def test_label_refuses_a_shard_that_no_longer_matches_its_index(
        data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Even when the damage is in a block no rule reads, and with --workers 1."""
    import shutil

    from tests.data.test_storage import flip_byte_in_chunk

    copy = tmp_path / "d"
    shutil.copytree(data, copy)
    for name in ("labels.parquet", "stack_labels.parquet", "labels.sha256"):
        (copy / name).unlink(missing_ok=True)
    flip_byte_in_chunk(copy / "shard-00000.h5", "screen/height_map")  # no built-in rule reads it
    code, _, err = run_cli(["label", str(copy), "--workers", "1", "--no-progress"], capsys)
    assert_one_line_error(code, err, "shard-00000.h5 does not match the sha256 the index "
                                     "recorded")
    assert not (copy / "labels.parquet").exists()
