"""Start-up time of the ``sc2data`` command: seconds from exec to exit for cheap commands.

Every CLI call (and so every CLI test, doc block and ``make demo`` step) pays the interpreter's
start and the imports of :mod:`sc2data.cli.commands` before any work. This times whole processes —
``python -m sc2data.cli ARGS`` — for ``--version``, ``--help`` and ``info DATA`` (a small dataset
rolled out once into a temporary folder), and ``python -c "import torch"`` for scale. Figures are
medians over ``--repeats`` runs.

``--ref DIR`` also times another checkout (e.g. ``git worktree add --detach DIR main``) with the
same interpreter, alternated run by run with this one so both see the same load, and prints the
ratio.

    python benchmarks/bench_startup.py
    python benchmarks/bench_startup.py --ref /tmp/sc2data-main --repeats 9
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def seconds(tree: Path, args: list[str]) -> float:
    """Wall seconds of one ``python -m sc2data.cli ARGS`` (or ``python ARGS`` after ``-c``) with
    ``tree`` first on the path."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    cmd = [sys.executable, *args] if args[0] == "-c" else [sys.executable, "-m", "sc2data.cli",
                                                            *args]
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, cwd=tree, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--ref", type=Path, help="another sc2data checkout to time alongside")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "data"
        subprocess.run([sys.executable, "-m", "sc2data.cli", "rollout", "--episodes", "1",
                        "--max-steps", "50", "--no-progress", "--out", str(data)], cwd=ROOT,
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, check=True,
                       stdout=subprocess.DEVNULL)
        cases = {"sc2data --version": ["--version"], "sc2data --help": ["--help"],
                 "sc2data info DATA": ["info", str(data)],
                 "python -c 'import torch'": ["-c", "import torch"]}
        trees = {"this": ROOT, **({"ref": a.ref.resolve()} if a.ref else {})}
        times: dict[tuple[str, str], list[float]] = {}
        for _ in range(a.repeats):
            for case, args in cases.items():
                for name, tree in trees.items():
                    times.setdefault((case, name), []).append(seconds(tree, args))
    print(f"# {platform.node()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
          f"median of {a.repeats}")
    head = "| command | this (s) |" + (" ref (s) | this / ref |" if a.ref else "")
    print(head)
    print("| --- | ---: |" + (" ---: | ---: |" if a.ref else ""))
    for case in cases:
        this = statistics.median(times[case, "this"])
        row = f"| `{case}` | {this:.2f} |"
        if a.ref:
            ref = statistics.median(times[case, "ref"])
            row += f" {ref:.2f} | {this / ref:.2f} |"
        print(row)


if __name__ == "__main__":
    main()
