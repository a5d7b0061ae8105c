"""``sc2data render DATA``: stored stacks by (episode, step) and the stacks a rule fired on, drawn
from a tiny rollout as a user runs it; every bad input is one line, with no PNG left behind."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from matplotlib import image

from sc2data.data.dataset import open_dataset
from sc2data.game.render import SCALE, colorize, empty_tiles, feature, layout, legend, stack_frames
from sc2data.ground.files import PARTIAL
from sc2data.labels.store import read_labels
from sc2data.labels.view import spread
from sc2data.schema import Schema
from tests.cli import assert_one_line_error, exit_code, run_cli

STEPS = 120
"""Long enough for the scripted agent to complete two SCVs (build_scv fires at steps 81, 115)."""
PNG = b"\x89PNG\r\n\x1a\n"


def cli(args: list[object], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    return run_cli([str(a) for a in args], capsys)


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One labelled episode of the scripted agent, cut at :data:`STEPS` steps."""
    out = tmp_path_factory.mktemp("view") / "tiny"
    assert exit_code("rollout", "--agent", "scripted", "--episodes", 1, "--max-steps", STEPS,
                     "--out", out, "--no-progress") == 0
    assert exit_code("label", out, "--no-progress") == 0
    return out


def fired(data: Path, rule: str) -> list[int]:
    t = read_labels(data).fired.to_pylist()
    return sorted(r["step"] for r in t if r["rule_id"] == rule)


def assert_no_png(folder: Path) -> None:
    left = [p.name for p in folder.rglob("*") if p.suffix == ".png" or PARTIAL in p.name]
    assert not left, left


def test_a_stored_stack_is_drawn_frame_by_frame(data: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    step = fired(data, "build_scv")[0]  # an SCV appears: the two frames differ
    out = tmp_path / "sub" / "stack.png"
    code, stdout, err = cli(["render", data, "--episode", 0, "--step", step, "--out", out],
                            capsys)
    assert code == 0, err
    assert stdout.strip() == f"wrote {out}"
    assert out.read_bytes()[:8] == PNG
    png = (image.imread(out)[..., :3] * 255).round()
    schema = Schema.paper()
    width, height, origins = layout(len(schema.screen), len(schema.minimap), 64, frames=2,
                                    header_lines=3)
    assert png.shape[:2] == (height, width)
    with open_dataset(data) as ds:
        frames = stack_frames(ds[0, step])
    assert not np.array_equal(frames[0]["screen/unit_type"], frames[1]["screen/unit_type"])
    keys = [l.key for l in schema.layers]
    for key in ("screen/unit_type", "screen/unit_hit_points", "minimap/player_relative"):
        for frame, (x, y) in zip(frames, origins[keys.index(key)], strict=True):
            drawn = png[y + SCALE // 2:y + 64 * SCALE:SCALE, x + SCALE // 2:x + 64 * SCALE:SCALE]
            assert np.array_equal(drawn, colorize(feature(key), frame[key])), key


def test_the_stored_stacks_legend_and_empty_layers(data: Path) -> None:
    with open_dataset(data) as ds:
        frames = stack_frames(ds[0, 100])
    names = {e.name for e in legend("screen/unit_type", [f["screen/unit_type"] for f in frames])}
    assert {"Terran.CommandCenter", "Terran.SCV", "Neutral.MineralField"} <= names
    assert "Terran.Marine" not in names, "no marine within 120 steps"
    keys = [l.key for l in Schema.paper().layers]
    empty = set(empty_tiles(frames, keys))
    assert {("screen/creep", 0), ("screen/creep", 1), ("screen/unit_energy", 1)} <= empty
    assert not {k for k, _ in empty} & {"screen/unit_type", "screen/player_relative"}


def test_default_out_is_named_after_the_data_and_the_stack(
        data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    code, _, err = cli(["render", data, "--episode", 0, "--step", 0], capsys)
    assert code == 0, err
    assert (tmp_path / "tiny-e0-s0.png").read_bytes()[:8] == PNG


def test_rule_writes_one_png_per_stack_it_fired_on(data: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    steps = fired(data, "build_scv")
    assert len(steps) >= 2, steps
    code, stdout, err = cli(["render", data, "--rule", "build_scv", "--out", tmp_path / "scv"],
                            capsys)
    assert code == 0, err
    written = sorted((tmp_path / "scv").iterdir())
    assert sorted(p.name for p in written) == sorted(f"e0-s{s}.png" for s in steps)
    assert all(p.read_bytes()[:8] == PNG for p in written)
    assert stdout.strip().splitlines() == [f"wrote {tmp_path / 'scv' / f'e0-s{s}.png'}"
                                           for s in steps]
    code, _, err = cli(["render", data, "--rule", "build_scv", "--limit", 1, "--out",
                        tmp_path / "one"], capsys)
    assert code == 0, err
    assert [p.name for p in (tmp_path / "one").iterdir()] == [f"e0-s{steps[0]}.png"]


def test_spread_keeps_first_and_last() -> None:
    assert spread(10, 3) == [0, 4, 9]
    assert spread(2, 8) == [0, 1]
    assert spread(5, 1) == [0]
    assert spread(100, 8)[-1] == 99 and len(spread(100, 8)) == 8


@pytest.fixture(scope="module")
def unlabelled(data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return Path(shutil.copytree(data, tmp_path_factory.mktemp("u") / "bare",
                                ignore=shutil.ignore_patterns("*labels*")))


@pytest.fixture(scope="module")
def stale(data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Another rollout (seed 1) carrying the labels of :func:`data`."""
    out = tmp_path_factory.mktemp("s") / "stale"
    assert exit_code("rollout", "--agent", "scripted", "--seed", 1, "--episodes", 1,
                     "--max-steps", 40, "--out", out, "--no-progress") == 0
    for f in data.glob("*labels*"):
        shutil.copy(f, out / f.name)
    return out


@pytest.mark.parametrize("args, needles", [
    (["--episode", 3, "--step", 0], ["episode 3 is not in", "episodes 0..0"]),
    (["--episode", 0, "--step", STEPS], [f"step {STEPS} is outside episode 0", "0..119"]),
    (["--episode", 0, "--step", -1], ["step -1 is outside episode 0"]),
    (["--episode", 0], ["give --episode E --step S, or --rule RULE"]),
    (["--step", 4], ["give --episode E --step S, or --rule RULE"]),
    ([], ["give --episode E --step S, or --rule RULE"]),
    (["--episode", 0, "--step", 1, "--limit", 2], ["give --episode E --step S, or --rule"]),
    (["--rule", "build_scv", "--step", 1], ["leave out --episode and --step"]),
    (["--rule", "make_coffee"], ["rule 'make_coffee' is not among the labels", (
        "--rules build_scv,collect_minerals,build_supply_depot,build_barracks,train_marine,"
        "make_coffee --overwrite")]),
    (["--rule", "train_marine"], ["rule 'train_marine' fired on none of the 120 stacks"]),
    (["--rule", "build_scv", "--limit", 0], ["--limit must be at least 1, not 0"]),
    (["--episode", 0, "--step", 1, "--agent", "scripted"], ["--agent is for a live render"]),
    (["--episode", 0, "--step", 1, "--steps", 5], ["--steps is for a live render"]),
])
def test_bad_stack_or_rule_is_one_line(data: Path, tmp_path: Path, args: list[object],
                                       needles: list[str],
                                       capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = cli(["render", data, *args, "--out", tmp_path / "x.png"], capsys)
    assert_one_line_error(code, err, *needles)
    assert_no_png(tmp_path)


@pytest.mark.parametrize("folder, args, needles", [
    ("empty", ["--episode", 0, "--step", 0], ["is not an sc2data dataset (no dataset.json)"]),
    ("empty", ["--rule", "build_scv"], ["is not an sc2data dataset (no dataset.json)"]),
    ("missing", ["--episode", 0, "--step", 0], ["is not a folder"]),
    ("unlabelled", ["--rule", "build_scv"], ["no labels in", "run sc2data label"]),
    ("stale", ["--rule", "build_scv"], ["were made from other data", "rerun sc2data label"]),
])
def test_a_folder_that_is_no_labelled_dataset_is_one_line(
        folder: str, args: list[object], needles: list[str], tmp_path: Path,
        request: pytest.FixtureRequest, capsys: pytest.CaptureFixture[str]) -> None:
    where = {"empty": tmp_path / "empty", "missing": tmp_path / "missing"}.get(folder)
    if folder == "empty":
        where.mkdir()  # type: ignore[union-attr]
    elif where is None:
        where = request.getfixturevalue(folder)
    out = tmp_path / "out"
    out.mkdir()
    code, _, err = cli(["render", where, *args, "--out", out / "x.png"], capsys)
    assert_one_line_error(code, err, *needles)
    assert_no_png(out)


@pytest.mark.parametrize("args", [["--episode", 0, "--step", 1], ["--rule", "build_scv"]])
def test_out_under_a_regular_file_is_one_line(data: Path, tmp_path: Path, args: list[object],
                                              capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    code, _, err = cli(["render", data, *args, "--out", blocker / "x"], capsys)
    assert_one_line_error(code, err, "cannot write the PNG to", str(blocker))
    assert blocker.read_text() == "not a folder"
    assert_no_png(tmp_path)


def test_rule_out_naming_a_file_and_stack_out_naming_a_folder(
        data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("mine")
    code, _, err = cli(["render", data, "--rule", "build_scv", "--out", blocker], capsys)
    assert_one_line_error(code, err, "is a file; with --rule, --out names a folder")
    folder = tmp_path / "folder"
    folder.mkdir()
    code, _, err = cli(["render", data, "--episode", 0, "--step", 1, "--out", folder], capsys)
    assert_one_line_error(code, err, "cannot write the PNG to", str(folder))
    assert blocker.read_text() == "mine" and not list(folder.iterdir())
    assert_no_png(tmp_path)


@pytest.mark.parametrize("args, needles", [
    (["--episode", 0, "--step", 0, "--out", "x.png"], ["--episode draws stored stacks", "DATA"]),
    (["--rule", "build_scv", "--out", "x"], ["--rule draws stored stacks"]),
    (["--steps", 1], ["a live render needs --out PNG"]),
])
def test_live_render_options_are_checked(args: list[object], needles: list[str], tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    code, _, err = cli(["render", *args], capsys)
    assert_one_line_error(code, err, *needles)
    assert_no_png(tmp_path)

