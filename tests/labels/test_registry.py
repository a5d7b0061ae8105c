"""Finding, validating and selecting rules: entry points, --rules-dir, and every way to be bad."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from sc2data.ground.errors import Sc2DataError
from sc2data.labels.registry import RuleError, load_registry, load_rules_dir, parse_ids
from sc2data.rulebase import blank_frame, set_field, stack
from tests.cli import exit_code

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "sc2data-rule-example"
BUILTIN = ["build_scv", "collect_minerals", "build_supply_depot", "build_barracks", "train_marine"]

HEADER = """
import numpy as np
from sc2data.rulebase import Rule, rule, rose
"""


def write_rule(folder: Path, name: str, body: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(HEADER + textwrap.dedent(body))
    return path


GOOD = """
class MoreMinerals(Rule):
    \"\"\"Minerals rose.\"\"\"
    id = "{id}"
    command = "have more minerals"
    requires = ("player",)
    def __call__(self, batch):
        return rose(batch.vector("player", "minerals"))

RULES = [MoreMinerals]
"""




# -- discovery -------------------------------------------------------------------------------------

def test_builtins_come_through_the_entry_point() -> None:
    registry = load_registry()
    assert list(registry.ids)[:5] == BUILTIN
    assert all("entry point builtin: sc2data.rules" in registry.get(i).source for i in BUILTIN)
    assert len(load_registry(entry_points=False)) == 0


def test_rules_dir_files(tmp_path: Path) -> None:
    write_rule(tmp_path, "a.py", GOOD.format(id="more_minerals"))
    write_rule(tmp_path, "b.py", """
        @rule(id="gas_up", command="gather gas", requires=["player"])
        def gas_up(batch):
            return rose(batch.vector("player", "vespene"))
        """)
    write_rule(tmp_path, "_helpers.py", "raise RuntimeError('never imported')")
    registry = load_registry(tmp_path)
    assert list(registry.ids) == BUILTIN + ["more_minerals", "gas_up"]
    assert registry.get("gas_up").source == f"file {tmp_path / 'b.py'}"
    a, b = blank_frame(), blank_frame()
    set_field(b, "player", "minerals", 5)
    assert registry.get("more_minerals").rule(stack([(a, b)])).tolist() == [True]


def test_selection() -> None:
    registry = load_registry()
    assert [e.id for e in registry.select(["train_marine", "build_scv"])] == \
        ["build_scv", "train_marine"]
    assert [e.id for e in registry.select(None, ["collect_minerals"])] == \
        [i for i in BUILTIN if i != "collect_minerals"]
    with pytest.raises(RuleError, match=r"unknown rule id 'build_cc'; known rules: build_scv, "):
        registry.select(["build_cc"])
    with pytest.raises(RuleError, match="unknown rule id 'nope'"):
        registry.select(None, ["nope"])
    with pytest.raises(RuleError, match="no rules selected"):
        registry.select(["build_scv"], ["build_scv"])
    assert parse_ids(" a, b ,,c ") == ["a", "b", "c"] and parse_ids("  ") is None


# -- validation: each bad rule is named, with what is wrong ---------------------------------------

BAD = {
    "bad_id": (GOOD.format(id="Build-It"), r"rule 'Build-It' from file .*bad_id\.py has id "
                                           r"'Build-It'; an id must be snake_case"),
    "unknown_key": ("""
        @rule(id="reads_fog", command="see fog", requires=["screen/fog_of_war"])
        def f(batch):
            return np.zeros(len(batch), bool)
        """, r"rule 'reads_fog' .* requires unknown schema key 'screen/fog_of_war'"),
    "undeclared": ("""
        @rule(id="sneaky", command="sneak", requires=["player"])
        def f(batch):
            return batch.layer("screen/unit_type")[:, 1, 0, 0] > 0
        """, r"rule 'sneaky' .* reads data it does not list in requires \('player',\) "
             r"\(the data has no layer 'screen/unit_type'"),
    "raises": ("""
        @rule(id="crashy", command="crash", requires=["player"])
        def f(batch):
            raise ZeroDivisionError("division by zero")
        """, r"rule 'crashy' from file .*raises\.py raised ZeroDivisionError: division by zero"),
    "shape": ("""
        @rule(id="wide", command="be wide", requires=["player"])
        def f(batch):
            return np.zeros((len(batch), 2), bool)
        """, r"rule 'wide' .* returned bool array of shape \(5, 2\) .* must return a \(5,\) bool"),
    "dtype": ("""
        @rule(id="counts", command="count", requires=["player"])
        def f(batch):
            minerals = batch.vector("player", "minerals")
            return minerals[:, 1] - minerals[:, 0]
        """, r"rule 'counts' .* returned int32 array of shape \(5,\) for 5 stacks "
             r"\(a synthetic batch\)"),
    "a_list": ("""
        @rule(id="listy", command="list", requires=["player"])
        def f(batch):
            return [True] * len(batch)
        """, r"rule 'listy' .* returned list"),
    "version": ("""
        @rule(id="old", command="be old", requires=["player"], version=0)
        def f(batch):
            return np.zeros(len(batch), bool)
        """, r"rule 'old' .* has version 0"),
    "no_requires": ("""
        @rule(id="blind", command="see nothing", requires=[])
        def f(batch):
            return np.zeros(len(batch), bool)
        """, r"rule 'blind' .* must list the schema keys it reads"),
    "import_error": ("import not_a_module_anywhere\n",
                     r"rule file .*import_error\.py failed to import: ModuleNotFoundError"),
    "empty": ("X = 1\n", r"rule file .*empty\.py defines no rules"),
    "needs_args": ("""
        class Param(Rule):
            id, command, requires = "param", "param", ("player",)
            def __init__(self, threshold):
                self.threshold = threshold
        RULES = [Param]
        """, r"rule class Param from file .* cannot be built with no arguments"),
}


@pytest.mark.parametrize("name", list(BAD))
def test_bad_rule_is_named(tmp_path: Path, name: str) -> None:
    body, message = BAD[name]
    write_rule(tmp_path, f"{name}.py", body)
    with pytest.raises(RuleError, match=message):
        load_rules_dir(tmp_path)


def test_duplicate_ids_name_both_sources(tmp_path: Path) -> None:
    write_rule(tmp_path, "one.py", GOOD.format(id="more_minerals"))
    write_rule(tmp_path, "two.py", GOOD.format(id="more_minerals"))
    with pytest.raises(RuleError, match=r"rule id 'more_minerals' is defined twice: by file "
                                        r".*one\.py and by file .*two\.py"):
        load_registry(tmp_path)
    shutil.rmtree(tmp_path)
    write_rule(tmp_path, "mine.py", GOOD.format(id="build_scv"))
    with pytest.raises(RuleError, match=r"'build_scv' is defined twice: by sc2data .* \(entry "
                                        r"point builtin: sc2data.rules\) and by file .*mine\.py"):
        load_registry(tmp_path)


def fake_plugin(site: Path, name: str, module_source: str, target: str) -> None:
    """An installed-looking distribution: a module plus a .dist-info with one entry point."""
    (site / f"{name}.py").write_text(textwrap.dedent(module_source))
    info = site / f"{name}-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[sc2data.rules]\nplug = {target}\n")


def test_broken_entry_point_plugins_are_named(tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    fake_plugin(tmp_path, "brokenplug", "raise ImportError('needs torch')\n", "brokenplug")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(RuleError, match=r"rule plugin brokenplug 1.0 \(entry point plug: "
                                        r"brokenplug\) failed to import: ImportError: needs torch"):
        load_registry()


def test_entry_point_module_without_rules(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fake_plugin(tmp_path, "emptyplug", "X = 1\n", "emptyplug")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(RuleError, match=r"emptyplug 1.0 .* has no RULES"):
        load_registry()


def test_entry_point_naming_one_rule_object(tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    fake_plugin(tmp_path, "oneplug", HEADER + GOOD.format(id="more_minerals"),
                "oneplug:MoreMinerals")
    monkeypatch.syspath_prepend(str(tmp_path))
    entry = load_registry().get("more_minerals")
    assert entry.source == "oneplug 1.0 (entry point plug: oneplug:MoreMinerals)"


# -- the CLI --------------------------------------------------------------------------------------

def test_cli_rules_list(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    write_rule(tmp_path, "mine.py", GOOD.format(id="more_minerals"))
    assert exit_code("rules", "list", "--rules-dir", str(tmp_path)) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split() == ["ID", "VERSION", "COMMAND", "SOURCE"]
    assert out[1].split()[:4] == ["build_scv", "1", "build", "an"]
    assert "entry point builtin" in out[1]
    assert out[-1].startswith("more_minerals") and out[-1].endswith(f"file {tmp_path}/mine.py")


@pytest.mark.parametrize("name", ["raises", "shape", "undeclared"])
def test_cli_bad_rule_is_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                  name: str) -> None:
    write_rule(tmp_path, f"{name}.py", BAD[name][0])
    assert exit_code("rules", "list", "--rules-dir", str(tmp_path)) == 2
    err = capsys.readouterr().err
    assert err.startswith("sc2data: error: rule ") and err.count("\n") == 1
    assert issubclass(RuleError, Sc2DataError)


def test_cli_rules_dir_missing(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert exit_code("rules", "list", "--rules-dir", str(tmp_path / "nope")) == 2
    assert "is not a folder" in capsys.readouterr().err


# -- the example plugin package, installed with pip and found through its entry point --------------

@pytest.fixture(scope="module")
def installed_example(tmp_path_factory: pytest.TempPathFactory) -> Path:
    work = tmp_path_factory.mktemp("example")
    src = shutil.copytree(EXAMPLE, work / "src",
                          ignore=shutil.ignore_patterns("build", "*.egg-info"))
    site = work / "site"
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                           "--no-build-isolation", "--no-index", "--target", str(site), str(src)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return site


def test_example_plugin_is_discovered_through_its_entry_point(
        installed_example: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    info = installed_example / "sc2data_rule_example-0.1.0.dist-info"
    assert (info / "entry_points.txt").is_file()
    monkeypatch.syspath_prepend(str(installed_example))
    entry = load_registry().get("finish_supply_depot")
    assert entry.source == ("sc2data-rule-example 0.1.0 (entry point example: "
                            "sc2data_rule_example)")
    a, b = blank_frame(), blank_frame()
    set_field(a, "player", "food_cap", 15)
    set_field(b, "player", "food_cap", 23)
    assert entry.rule(stack([(a, b), (b, b)])).tolist() == [True, False]


def test_example_plugin_in_the_installed_cli(installed_example: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(installed_example)}
    exe = Path(sys.executable).with_name("sc2data")
    proc = subprocess.run([str(exe), "rules", "list"], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr
    line = next(l for l in proc.stdout.splitlines() if l.startswith("finish_supply_depot"))
    assert "finish a supply depot" in line and "sc2data-rule-example 0.1.0" in line
