"""Every Python and shell block of README.md and docs/*.md runs, as a reader would run it.

Blocks run in file order in one working folder (a copy of ``manifests/`` plus ``tiny.toml``), so a
later block reads what an earlier one made, as in the README; the Python blocks of one file
share a namespace. Sizes shrink through :data:`SUBSTITUTIONS` (each must still match its block,
so the map cannot rot); a block that truly cannot run here (it needs StarCraft II, a GPU or a Ray
cluster, or would run this suite itself) carries ``<!-- skip-test: reason -->`` on the line
before it.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
RUN = {"python": "python", "py": "python", "bash": "shell", "sh": "shell", "shell": "shell",
       "console": "shell"}
"""Fence languages that run, and how."""
SKIP = re.compile(r"^<!--\s*skip-test:\s*(.+?)\s*-->$")

SUBSTITUTIONS: list[tuple[str, str]] = [
    ("--episodes 20 --workers 2", "--episodes 3 --workers 2"),
    ("--out data/rr --episodes 24", "--out data/rr --episodes 4"),
    ("pair manifests/smoke.toml", "pair manifests/tiny.toml"),
    ("sc2data build manifests/buildmarines-paper.toml --out data/paper",
     "sc2data build manifests/tiny.toml --out demo-out/data"),
    ("sc2data train data/paper/pairs --out runs/paper",
     "sc2data train demo-out/data/pairs --out demo-out/run --epochs 1 --threads 1 "
     "--vocab-size 2000 --no-progress"),
    ("sc2data train data/rr-pairs --out runs/mem",
     "sc2data train data/rr-pairs --out runs/mem --epochs 1 --threads 1 --vocab-size 2000 "
     "--no-progress"),
    ("sc2data label DATA", "sc2data label data/rr"),
    # docs/rules.md: the recipe with the reader's new command, at the tiny recipe's counts.
    ("cp manifests/smoke.toml my-recipe.toml", "cp manifests/tiny.toml my-recipe.toml"),
    ("--data DATA --out my-pairs", "--data data/rr --out my-pairs"),
    ("for _ in range(100):", "for _ in range(20):"),
    ("--steps 20000", "--steps 64 --rollout 32 --batch-size 32 --episode-steps 40 "
                      "--checkpoint-every 64 --no-progress"),
    ("sc2data rl evaluate runs/rl-narr --episodes 10",
     "sc2data rl evaluate runs/rl-narr --episodes 1"),
    # docs/mem-loop.md: 3 episodes a source, the tiny recipe's counts, a tiny MEM and agent.
    ("--episodes 20 --workers 2 --out loop/data/random",
     "--episodes 3 --workers 2 --out loop/data/random"),
    ("--episodes 20 --workers 2 --out loop/data/policy",
     "--episodes 3 --workers 2 --out loop/data/policy"),
    ("pair manifests/smoke.toml --data loop/data/random",
     "pair manifests/tiny.toml --data loop/data/random"),
    ("sc2data pair manifests/mem-loop.toml",
     "sed -e 's/= 40$/= 3/' -e 's/= 200$/= 12/' manifests/mem-loop.toml > manifests/tiny-loop.toml"
     " && sc2data pair manifests/tiny-loop.toml"),
    ("--out loop/mem-0\n", "--out loop/mem-0 --epochs 1 --threads 1 --vocab-size 2000 "
                            "--no-progress\n"),
    ("--out loop/mem-1\n", "--out loop/mem-1 --epochs 1 --threads 1 --vocab-size 2000 "
                            "--no-progress\n"),
    ("--epochs 3 --out loop/mem-1-tuned", "--epochs 1 --out loop/mem-1-tuned --threads 1 "
                                          "--vocab-size 2000 --no-progress"),
    ("--steps 65536", "--steps 64 --rollout 32 --batch-size 32 --episode-steps 40 "
                      "--checkpoint-every 64 --no-progress"),
    ("--steps 131072", "--steps 128 --rollout 32 --batch-size 32 --episode-steps 40 "
                       "--checkpoint-every 64 --no-progress"),
    ("--episodes 10\n", "--episodes 1\n"),
]
"""(text in a block, what runs instead): the README's sizes made small. The build block writes
what ``make demo`` would (``demo-out/``), which later blocks read."""

TINY_RECIPE = {"episodes = 20": "episodes = 3", "states_per_command = 40": "states_per_command = 3",
               "null_states = 200": "null_states = 12", 'name = "smoke"': 'name = "tiny"'}
"""``manifests/tiny.toml``: the smoke recipe at a size three episodes fill."""


@dataclass(frozen=True)
class Block:
    path: Path
    line: int
    kind: str
    text: str
    skip: str | None

    @property
    def id(self) -> str:
        return f"{self.path.name}:{self.line}"


def blocks(path: Path) -> list[Block]:
    """The fenced blocks of ``path`` in a language that runs, with their skip reasons."""
    out, lines = [], path.read_text().splitlines()
    i = 0
    while i < len(lines):
        m = re.match(r"^```(\w*)\s*$", lines[i])
        if not m:
            i += 1
            continue
        start, lang = i, m.group(1)
        j = i + 1
        while not lines[j].startswith("```"):
            j += 1
        before = next((lines[k].strip() for k in range(start - 1, -1, -1) if lines[k].strip()), "")
        skip = SKIP.match(before)
        if lang in RUN:
            out.append(Block(path, start + 1, RUN[lang], "\n".join(lines[start + 1:j]) + "\n",
                             skip.group(1) if skip else None))
        i = j + 1
    return out


ALL = [b for p in DOCS for b in blocks(p)]
USED: set[str] = set()
NAMESPACES: dict[Path, dict[str, Any]] = {}


def substituted(text: str) -> str:
    for old, new in SUBSTITUTIONS:
        if old in text:
            USED.add(old)
            text = text.replace(old, new)
    return text


@pytest.fixture(scope="session")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reader's folder: ``manifests/`` (plus ``tiny.toml``) and the rule file docs/rules.md
    asks to save as ``my_rules/finish_depot.py``."""
    work = tmp_path_factory.mktemp("docs")
    shutil.copytree(ROOT / "manifests", work / "manifests")
    tiny = (ROOT / "manifests" / "smoke.toml").read_text()
    for old, new in TINY_RECIPE.items():
        assert old in tiny, old
        tiny = tiny.replace(old, new)
    (work / "manifests" / "tiny.toml").write_text(tiny)
    rule = next(b for b in ALL if "class FinishSupplyDepot" in b.text)
    (work / "my_rules").mkdir()
    (work / "my_rules" / "finish_depot.py").write_text(rule.text)
    return work


@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.parametrize("block", ALL, ids=[b.id for b in ALL])
def test_block_runs(block: Block, workdir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    if block.skip:
        pytest.skip(block.skip)
    monkeypatch.chdir(workdir)
    code = substituted(block.text)
    if block.kind == "python":
        namespace = NAMESPACES.setdefault(block.path, {"__name__": "__doc_block__"})
        exec(compile(code, f"{block.id}", "exec"), namespace)
        return
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    done = subprocess.run(["bash", "-euo", "pipefail", "-c", code], cwd=workdir, env=env,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"{block.id} failed:\n{code}\n{done.stdout[-3000:]}" \
                                 f"\n{done.stderr[-3000:]}"


def test_every_substitution_is_used() -> None:
    """Runs after the blocks (file order): a substitution no block contains any more is stale."""
    if not USED:
        pytest.skip("the blocks did not run (deselected)")
    texts = "".join(b.text for b in ALL if not b.skip)
    stale = [old for old, _ in SUBSTITUTIONS if old not in texts]
    assert not stale, f"substitutions matching no block: {stale}"


def test_the_parser_finds_blocks_and_skips() -> None:
    readme = [b for b in ALL if b.path.name == "README.md"]
    assert sum(b.kind == "python" for b in readme) >= 1
    assert sum(b.kind == "shell" for b in readme) >= 3
    assert sum(b.kind == "python" for b in ALL) >= 8
    assert all(b.skip for b in ALL if "make demo" in b.text)
