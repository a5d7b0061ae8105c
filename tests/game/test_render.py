"""render: a PNG of all feature layers, pixel-exact in pysc2's palettes, with legends of the
categorical layers' ids and "empty" notes; the CLI writes one of a live frame."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib import image

from sc2data._pysc2 import features, units  # first: it makes pysc2 importable on 3.11

from pysc2.env import mock_sc2_env  # isort: skip
from sc2data.cli import main
from sc2data.game.env import interface_format
from sc2data.game.render import (
    SCALE,
    Entry,
    colorize,
    empty_tiles,
    id_name,
    layout,
    legend,
    observation_frame,
    render_frame,
)

_S, _M = features.SCREEN_FEATURES, features.MINIMAP_FEATURES


def _observation() -> dict[str, Any]:
    """pysc2's mock observation (right keys, shapes, dtypes) with a few units drawn in."""
    env = mock_sc2_env.SC2TestEnv(agent_interface_format=[interface_format()])
    obs = {k: np.array(v) for k, v in env.reset()[0].observation.items()}
    screen = obs["feature_screen"]
    screen[_S.unit_type.index, 20:35, 16:31] = units.Terran.CommandCenter
    screen[_S.unit_type.index, 40:42, 50:52] = units.Terran.Marine
    screen[_S.player_relative.index, 20:35, 16:31] = features.PlayerRelative.SELF
    screen[_S.unit_hit_points.index, 20:35, 16:31] = 1500
    obs["feature_minimap"][_M.camera.index, 10:30, 10:40] = 1
    return obs


def _run(*argv: str) -> int:
    """Run the CLI in-process as the console script does; its exit status."""
    try:
        main(list(argv))
    except SystemExit as e:
        return int(e.code or 0)
    return 0


def _tile(png: np.ndarray, index: int, y: int, x: int) -> np.ndarray:
    """The RGB colour at layer pixel (y, x) of tile ``index``, read back from the PNG."""
    _, _, origins = layout(len(_S), len(_M), 64)
    ox, oy = origins[index][0]
    return png[oy + y * SCALE + SCALE // 2, ox + x * SCALE + SCALE // 2, :3]


def test_render_frame_writes_a_png_of_the_expected_size(tmp_path: Path) -> None:
    path = render_frame(_observation(), tmp_path / "sub" / "frame.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    width, height, origins = layout(len(_S), len(_M), 64)
    assert len(origins) == 27 + 11
    assert image.imread(path).shape[:2] == (height, width)


def test_unit_type_pixels_get_pysc2_palette_colours(tmp_path: Path) -> None:
    obs = _observation()
    png = (image.imread(render_frame(obs, tmp_path / "f.png"))[..., :3] * 255).round()
    palette = _S.unit_type.palette
    for y, x, unit in [(25, 20, units.Terran.CommandCenter), (41, 51, units.Terran.Marine),
                       (5, 5, 0)]:
        want = np.clip(palette[unit], 0, 255).astype(np.uint8)
        assert np.array_equal(_tile(png, _S.unit_type.index, y, x), want), unit
    assert not np.array_equal(palette[units.Terran.CommandCenter], palette[units.Terran.Marine])
    hp = np.clip(_S.unit_hit_points.color(np.array([1500])), 0, 255).astype(np.uint8)[0]
    assert np.array_equal(_tile(png, _S.unit_hit_points.index, 25, 20), hp)
    camera = 27 + _M.camera.index
    assert np.array_equal(_tile(png, camera, 20, 20), colorize(_M.camera, np.array([1]))[0])
    assert not np.array_equal(_tile(png, camera, 20, 20), _tile(png, camera, 50, 50))


def test_colorize_clips_values_beyond_the_palette() -> None:
    img = colorize(_S.visibility_map, np.array([[0, 2, 3]]))
    assert img.dtype == np.uint8 and img.shape == (1, 3, 3)
    assert np.array_equal(img[0, 2], img[0, 1])


def test_cli_render_plays_the_simulator_and_writes_the_png(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "frame.png"
    assert _run("render", "--steps", "40", "--seed", "3", "--agent", "reduced-random",
                "--out", str(out)) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    png = image.imread(out)
    width, height, _ = layout(len(_S), len(_M), 64)
    assert png.shape[:2] == (height, width)
    cc = _S.unit_type.palette[units.Terran.CommandCenter].astype(np.uint8)
    tile = (png[..., :3] * 255).round()
    assert (tile == cc).all(axis=-1).any(), "the Command Center is drawn"


def test_cli_render_unknown_agent_is_one_line(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    assert _run("render", "--agent", "grandmaster", "--out", str(tmp_path / "f.png")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["sc2data: error: unknown agent 'grandmaster'; choose one of: random, "
                   "reduced-random, scripted, macro-rules, policy:RUN"]


def test_unwritable_output_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    assert _run("render", "--steps", "1", "--out", str(blocker / "f.png")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sc2data: error: cannot write the PNG to")


def test_legend_names_the_ids_present_by_pysc2_name() -> None:
    obs = _observation()
    plane = obs["feature_screen"][_S.unit_type.index]
    entries = legend("screen/unit_type", [plane])
    assert [(e.id, e.name) for e in entries] == [
        (units.Terran.CommandCenter, "Terran.CommandCenter"),
        (units.Terran.Marine, "Terran.Marine")]
    cc = np.clip(_S.unit_type.palette[units.Terran.CommandCenter], 0, 255).astype(np.uint8)
    assert entries[0].color == tuple(int(c) for c in cc) and entries[0].frames == (0,)
    relative = legend("screen/player_relative", [obs["feature_screen"][_S.player_relative.index]])
    assert [e.name for e in relative] == ["PlayerRelative.SELF"]
    assert legend("screen/unit_hit_points", [obs["feature_screen"][_S.unit_hit_points.index]]) == []


def test_legend_marks_ids_held_by_one_frame_of_two() -> None:
    before, after = np.zeros((64, 64), np.uint16), np.zeros((64, 64), np.uint16)
    before[1, 1] = after[1, 1] = units.Terran.SCV
    after[5:9, 5:9] = units.Terran.Barracks
    entries = legend("screen/unit_type", [before, after])
    assert entries == [  # ascending ids
        Entry(units.Terran.Barracks, "Terran.Barracks", entries[0].color, (1,)),
        Entry(units.Terran.SCV, "Terran.SCV", entries[1].color, (0, 1))]
    assert legend("screen/unit_type", [before * 0, after * 0]) == [], "0 is the background"


@pytest.mark.parametrize("key, value, name", [
    ("minimap/visibility_map", 2, "Visibility.VISIBLE"),
    ("screen/player_id", 16, "neutral"),
    ("screen/player_id", 1, "player 1"),
    ("screen/selected", 1, "selected"),
    ("minimap/unit_type", 341, "Neutral.MineralField"),
    ("screen/unit_type", 2, "2"),  # no unit has id 2
])
def test_id_names(key: str, value: int, name: str) -> None:
    assert id_name(key, value) == name


def test_empty_tiles_are_the_all_zero_layers_of_each_frame() -> None:
    frame = observation_frame(_observation())
    keys = [k for k in frame if "/" in k]
    empty = {k for k, _ in empty_tiles([frame], keys)}
    assert "screen/creep" in empty and "screen/effects" in empty
    assert not {"screen/unit_type", "screen/player_relative", "minimap/camera"} & empty
    cur = {k: v.copy() for k, v in frame.items()}
    cur["screen/creep"][3, 3] = 1
    assert ("screen/creep", 0) in empty_tiles([frame, cur], keys)
    assert ("screen/creep", 1) not in empty_tiles([frame, cur], keys)
