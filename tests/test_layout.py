"""The package's layout holds: imports flow one way, from the shared ground up through the stages.

Ground (``sc2data.ground``; and at the root ``rulebase``, ``schema``, ``_pysc2``, what rule plugins
import) ← game ← data ← labels ← pairs ← model, with RL, scale-out and testing helpers beside the
top; the command line (``sc2data.cli``), the build driver, the folder inspector and the package's
lazy public API above all. A module may import its own level or lower ones, never a higher one —
at module level or inside a function (only imports for type checking are exempt).
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "sc2data"
LEVELS = {"ground": 0, "game": 1, "data": 2, "labels": 3, "pairs": 4, "model": 5, "rl": 6,
          "scaleout": 6, "testing": 6, "cli": 7}
TOP = {"build", "folders", "__init__"}
"""Root modules that sit above every stage: the build driver, the folder inspector (info/verify
of any folder) and the lazy public API; any other root module is shared ground."""
ROOT_MODULES = 6
"""At most this many modules at the package root: the rest say what they are by their folder."""


def level(module: str) -> int:
    """The level of ``sc2data.X[.…]``: 0 for shared ground, 7 for the top."""
    parts = module.split(".")
    if len(parts) == 1:
        return 7
    if parts[1] in LEVELS:
        return LEVELS[parts[1]]
    return 7 if parts[1] in TOP else 0


def imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every ``sc2data`` import outside ``if TYPE_CHECKING:`` blocks."""
    tree = ast.parse(path.read_text())
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip |= {id(n) for n in ast.walk(node)}
    found = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("sc2data"):
            if node.module == "sc2data":  # `from sc2data import dataset`: submodules by name
                found += [(node.lineno, f"sc2data.{a.name}") for a in node.names]
            else:
                found.append((node.lineno, node.module))
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.startswith("sc2data")]
    return found


def test_imports_never_go_upward() -> None:
    upward = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        me = ".".join(rel.parts)
        mine = level(me)
        for line, target in imports(path):
            if target == "sc2data" or target.startswith("sc2data.rules"):
                continue
            if level(target) > mine:
                upward.append(f"{rel}.py:{line} imports {target}")
    assert not upward, "\n".join(upward)


def test_the_root_holds_few_modules() -> None:
    root = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(root) <= ROOT_MODULES, root


def test_levels_name_every_subpackage() -> None:
    subpackages = {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    assert subpackages <= set(LEVELS), subpackages - set(LEVELS)


def test_commands_start_without_torch_or_the_real_games_environment() -> None:
    """Every ``sc2data`` process imports :mod:`sc2data.cli.commands`: it must not pull in torch or
    pysc2's ``sc2_env`` (whose renderer imports scikit-video and SciPy, 1.8 s of a 3.7 s start;
    BENCHMARKS.md, "Start-up and the test suite")."""
    import subprocess
    import sys

    heavy = ["torch", "pysc2.env.sc2_env", "scipy", "skvideo"]
    code = ("import sys, sc2data.cli.commands; "
            f"print(' '.join(m for m in {heavy!r} if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], cwd=PACKAGE.parent, capture_output=True,
                          text=True, check=True)
    assert done.stdout.strip() == "", f"sc2data.cli.commands imports {done.stdout.strip()}"


def _graph() -> dict[str, set[str]]:
    """Every ``sc2data`` module and the modules it imports anywhere (in functions, and for type
    checking too): ``from a.b import c`` counts ``a.b.c`` where that is a module."""
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        found: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("sc2data"):
                found |= {f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in modules
                          else str(node.module) for a in node.names}
            elif isinstance(node, ast.Import):
                found |= {a.name for a in node.names}
        graph[name] = found & modules.keys()
    return graph


def test_no_import_cycles() -> None:
    """No module reaches itself through imports, not even through one made for type checking or
    inside a function: a cycle means two modules that cannot be read apart."""
    graph = _graph()
    cycles = []
    for start in sorted(graph):
        seen, todo = set(), [(start, (start,))]
        while todo:
            node, path = todo.pop()
            for nxt in graph[node]:
                if nxt == start:
                    cycles.append(" → ".join((*path, start)))
                elif nxt not in seen:
                    seen.add(nxt)
                    todo.append((nxt, (*path, nxt)))
    assert not cycles, "\n".join(cycles)
