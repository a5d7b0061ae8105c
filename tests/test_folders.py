"""``sc2data info`` and ``verify`` on every kind of folder sc2data writes — a dataset, a pair set, a
training run, an RL run, a build — and their faults in one line whose remedy names only options
the named command has."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, run_cli
from tests.mem_helpers import tiny_pairset, train_tiny
from tests.synthetic_data import make_dataset


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("folders")
    build = root / "build"
    make_dataset(build / "rollout", episodes=2)
    pairs = tiny_pairset(build / "pairs")
    out = {"dataset": build / "rollout", "pair set": pairs, "build": build}
    try:
        import torch  # noqa: F401
    except ImportError:
        return out
    out["training run"] = train_tiny(pairs, root / "run", epochs=1)
    return out


@pytest.fixture(scope="module")
def rl_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("sb3_contrib")
    from tests.rl.test_cli import TINY

    run = tmp_path_factory.mktemp("rl") / "run"
    assert run_cli_plain(["rl", "train", "--out", run, *TINY]) == 0
    return run


def run_cli_plain(args: list[object]) -> int:
    from tests.cli import exit_code

    return exit_code(*args)


def options_of(command: list[str], capsys: pytest.CaptureFixture[str]) -> set[str]:
    code, out, _ = run_cli([*command, "--help"], capsys)
    assert code == 0
    return set(re.findall(r"--[a-z][a-z-]*", out))


def assert_remedies_exist(line: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Every ``sc2data CMD … --opt`` in ``line`` names an option CMD has."""
    for m in re.finditer(r"sc2data ((?:rl )?[a-z]+)([^;,()]*)", line):
        command, rest = m.group(1).split(), m.group(2)
        for opt in re.findall(r"--[a-z][a-z-]*", rest):
            assert opt in options_of(command, capsys), f"{line}: {command} has no {opt}"
    for opt in re.findall(r"(?:pick|choose) another (--[a-z-]+)", line):
        assert opt == "--out"


@pytest.mark.parametrize("what", ["dataset", "pair set", "build", "training run"])
def test_info_and_verify_on_each_folder_kind(folders: dict[str, Path], what: str,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    if what not in folders:
        pytest.skip("needs torch")
    folder = folders[what]
    code, out, err = run_cli(["info", folder], capsys)
    assert code == 0, err
    assert str(folder) in out
    code, out, err = run_cli(["verify", folder], capsys)
    assert code == 0, err
    assert out.startswith(f"{folder}: OK ({what}")


def test_a_build_folder_shows_and_checks_both_parts(folders: dict[str, Path],
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    build = folders["build"]
    code, out, _ = run_cli(["info", build], capsys)
    assert "dataset   " in out and "pair set  " in out and "codec     zstd+fletcher32" in out
    assert "{" not in out.split("codec", 1)[1].splitlines()[0]  # words, not a raw dict
    code, out, _ = run_cli(["verify", build], capsys)
    assert "rollout/" in out and "pairs/" in out
    copy = Path(shutil.copytree(build, build.parent / "damaged"))
    shard = next((copy / "rollout").glob("shard-*.h5"))
    shard.write_bytes(shard.read_bytes()[:-100])
    code, _, err = run_cli(["verify", copy], capsys)
    assert code == 1 and "FAULT" in err and shard.name in err


def test_info_and_verify_on_an_rl_run(rl_run: Path, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["info", rl_run], capsys)
    assert code == 0, err
    assert "RL run" in out and "96 decisions" in out and "reward    sparse" in out
    code, out, err = run_cli(["verify", rl_run], capsys)
    assert code == 0, err
    assert out.startswith(f"{rl_run}: OK (RL run")
    # Damage: the checkpoint, then a record; one fault or one line, with remedies that exist.
    copy = Path(shutil.copytree(rl_run, tmp_path / "copy"))
    model = copy / "model.zip"
    data = bytearray(model.read_bytes())
    data[len(data) // 2] ^= 0xFF
    model.write_bytes(bytes(data))
    code, _, err = run_cli(["verify", copy], capsys)
    assert code == 1 and "model.zip" in err
    assert_remedies_exist(err, capsys)
    state = json.loads((copy / "state.json").read_text())
    del state["timesteps"]
    (copy / "state.json").write_text(json.dumps(state))
    code, _, err = run_cli(["info", copy], capsys)
    assert_one_line_error(code, err, "state.json", "timesteps")
    assert_remedies_exist(err, capsys)


def test_commands_given_the_wrong_folder_say_which_to_pass(
        folders: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    recipe = Path(__file__).resolve().parents[1] / "manifests" / "smoke.toml"
    build, pairs = folders["build"], folders["pair set"]
    code, _, err = run_cli(["pair", recipe, "--data", pairs], capsys)
    assert_one_line_error(code, err, "is a pair set (sc2data pair), not a dataset", "--data")
    assert "rollout" not in err
    code, _, err = run_cli(["pair", recipe, "--data", build], capsys)
    assert_one_line_error(code, err, "is a build folder", str(build / "rollout"))
    code, _, err = run_cli(["label", pairs], capsys)
    assert_one_line_error(code, err, "is a pair set", "as DATA")
