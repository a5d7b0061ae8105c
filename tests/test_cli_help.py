"""One CLI voice: commands in pipeline order, positional names that say what they take, defaults
shown one way, one version command."""

from __future__ import annotations

import re

import pytest

from tests.cli import run_cli


def help_of(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    code, out, err = run_cli([*args, "--help"], capsys)
    assert code == 0, err
    return out


def test_commands_are_listed_in_pipeline_order(capsys: pytest.CaptureFixture[str]) -> None:
    from sc2data.cli.commands import PIPELINE

    out = help_of([], capsys)
    listed = re.findall(r"^  ([a-z]+)\s", out.split("Commands:", 1)[1], re.M)
    assert listed == list(PIPELINE)


def test_version_and_dash_dash_version_print_the_same(capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    code, version, _ = run_cli(["version"], capsys)
    assert code == 0
    code, dashed, _ = run_cli(["--version"], capsys)
    assert code == 0 and dashed == version
    names = [line.split()[0] for line in version.splitlines()]
    assert names[0] == "sc2data"
    assert {"torch", "stable-baselines3", "gymnasium", "pysc2"} <= set(names)


@pytest.mark.parametrize("command, metavar", [
    (["rollout"], "--out PATH"), (["label"], "DATA"), (["pair"], "RECIPE"),
    (["pair"], "--data DATA"), (["build"], "RECIPE"), (["train"], "PAIRS"),
    (["evaluate"], "RUN"), (["tsne"], "RUN"), (["export"], "DATA"), (["info"], "FOLDER"),
    (["verify"], "FOLDER"), (["render"], "[DATA]")])
def test_positional_names_say_what_they_take(command: list[str], metavar: str,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    out = help_of(command, capsys)
    assert metavar in out
    usage = out.split("\n\n", 1)[0]
    assert "{" not in usage and "<" not in usage, usage


@pytest.mark.parametrize("command", [
    ["rollout"], ["label"], ["pair"], ["build"], ["train"], ["evaluate"], ["tsne"], ["export"],
    ["render"], ["rl", "train"], ["rl", "evaluate"], ["rl", "baselines"], ["rl", "plot"],
    ["rl", "compare"], ["rl", "agreement"]])
def test_defaults_are_shown_one_way(command: list[str], capsys: pytest.CaptureFixture[str]
                                    ) -> None:
    out = " ".join(help_of(command, capsys).split())
    assert not re.search(r"\((?:default|default: [^)]*)\)", out), out
    odd = re.findall(r"(?<!sc2data)\[(?!default: |required\]|env var)[a-z0-9][^\]]*\]", out)
    assert not odd, odd  # "[1800]", "[one per core]": a default not written as [default: …]
    types = re.findall(r"<(?:str|path|file|int|float|bool|int range|float range|list\[\w+\])>",
                       out)
    assert not types, types  # a value's type in typer's words, not what it takes


def test_render_and_rollout_default_to_the_same_agent(capsys: pytest.CaptureFixture[str]) -> None:
    from sc2data.ground.recipe import RolloutSpec

    for command in (["rollout"], ["render"]):
        text = " ".join(help_of(command, capsys).split())
        assert f"[default: {RolloutSpec.agent}" in text, command
