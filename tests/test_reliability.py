"""Hostile recipes and options: each is one line naming the field, a non-zero exit, nothing
written (docs/reliability.md lists what is promised and which test holds it)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, run_cli

ROOT = Path(__file__).resolve().parents[1]
SMOKE = (ROOT / "manifests" / "smoke.toml").read_text()


def _recipe(tmp_path: Path, old: str, new: str) -> Path:
    assert old in SMOKE, old
    path = tmp_path / "r.toml"
    path.write_text(SMOKE.replace(old, new, 1))
    return path


@pytest.mark.parametrize("old, new, needles", [
    ('name = "smoke"', 'name = "../../x"', ["name '../../x' must be"]),
    ('name = "smoke"', 'name = "/abs/path"', ["name '/abs/path' must be"]),
    ('name = "smoke"', f'name = "{"n" * 5000}"', ["must be 1–64 letters"]),
    ("seed = 0", "seed = -1", ["seed must be a non-negative"]),
    ("episodes = 20", "episodes = 1000000000000", ["episodes must be at most 1,000,000"]),
    ("train = 0.666667", "train = nan", ["train, val and test must be positive"]),
    ('text = "train a marine"', f'text = "{"word " * 20000}"', ["characters long"]),
    ('paraphrases = ["make a soldier", "recruit a marine", "build a marine"]',
     'paraphrases = ["make a soldier", "recruit a marine", "build an SCV"]',
     ["'build an SCV' is already text 'build an SCV' of build_scv"]),
])
def test_hostile_recipe_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    old: str, new: str, needles: list[str]) -> None:
    recipe = _recipe(tmp_path, old, new)
    code, _, err = run_cli(["build", str(recipe), "--out", str(tmp_path / "out")], capsys)
    assert_one_line_error(code, err, *needles)
    assert not (tmp_path / "out").exists()


def test_binary_or_folder_recipe_is_one_line(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "bin.toml").write_bytes(bytes(range(256)) * 4)
    code, _, err = run_cli(["build", str(tmp_path / "bin.toml"), "--out", str(tmp_path / "o")],
                           capsys)
    assert_one_line_error(code, err, "is not a text file")
    code, _, err = run_cli(["build", str(tmp_path), "--out", str(tmp_path / "o")], capsys)
    assert_one_line_error(code, err, "is a folder")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("option, value, needle", [
    ("--lr", "nan", "--lr must be a positive number"),
    ("--l2", "-1", "--l2 must be zero or a positive"),
    ("--threads", "-2", "--threads must be at least 1"),
    ("--vocab-size", "0", "--vocab-size must be at least 1"),
    ("--epochs", "0", "--epochs must be at least 1"),
    ("--conv-channels", "0", "--conv-channels must be at least 1"),
])
def test_bad_train_option_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                      option: str, value: str, needle: str) -> None:
    code, _, err = run_cli(["train", str(tmp_path / "nowhere"), "--out", str(tmp_path / "run"),
                            option, value], capsys)
    assert_one_line_error(code, err, needle)
    assert not (tmp_path / "run").exists()


def test_rollout_refuses_absurd_episode_counts(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["rollout", "--episodes", "1000000000000", "--out",
                            str(tmp_path / "d")], capsys)
    assert_one_line_error(code, err, "episodes must be at most 1,000,000")
    assert not (tmp_path / "d").exists()


def test_build_names_an_unknown_rule_before_any_rollout(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    recipe = _recipe(tmp_path, "[commands.train_marine]", "[commands.train_marauder]")
    code, _, err = run_cli(["build", str(recipe), "--out", str(tmp_path / "out")], capsys)
    assert_one_line_error(code, err, "unknown rule id 'train_marauder'")
    assert not (tmp_path / "out").exists()  # nothing rolled out


def test_build_finds_rules_in_rules_dir(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rules = tmp_path / "my_rules"
    rules.mkdir()
    (rules / "late.py").write_text(
        "import numpy as np\nfrom sc2data.rulebase import rule\n"
        "@rule(id='train_marauder', command='train a marine', requires=['screen/unit_type'])\n"
        "def f(batch):\n    return np.zeros(len(batch), bool)\n")
    recipe = _recipe(tmp_path, "[commands.train_marine]", "[commands.train_marauder]")
    text = recipe.read_text().replace("layers = \"paper\"", "layers = \"paper\"\nepisodes = 1",
                                      ).replace("episodes = 20\n", "")
    recipe.write_text(text)
    code, _, err = run_cli(["build", str(recipe), "--out", str(tmp_path / "out"), "--rules-dir",
                            str(rules), "--no-progress"], capsys)
    # the rule is found, the data is rolled out and labelled; one episode has too few states
    assert "unknown rule" not in err and (tmp_path / "out" / "rollout" / "labels.parquet").exists()


def test_out_under_a_regular_file_is_one_line_before_any_work(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tests.mem_helpers import tiny_pairset, train_tiny

    blocker = tmp_path / "file"
    blocker.write_text("a file, not a folder")
    data = tiny_pairset(tmp_path / "pairs")
    run = train_tiny(data, tmp_path / "run", epochs=1)
    for args in (["train", data, "--out", blocker / "run", "--epochs", "1"],
                 ["tsne", run, "--out", blocker / "x" / "tsne.png"],
                 ["pair", ROOT / "manifests" / "smoke.toml", "--data", tmp_path / "nowhere",
                  "--out", blocker / "pairs"],
                 ["build", ROOT / "manifests" / "smoke.toml", "--out", blocker / "build"]):
        code, _, err = run_cli(args, capsys)
        assert_one_line_error(code, err, f"{blocker} is a file, not a folder", "--out")
    assert blocker.read_text() == "a file, not a folder"
    assert not list(tmp_path.glob("**/*.partial")) and not (run / "tsne.png").exists()
