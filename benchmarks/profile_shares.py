"""Where a process's time goes, from a py-spy sampling profile: the share of samples whose stack
holds each function.

py-spy (``pip install py-spy``; not a dependency of sc2data) samples a running process without
slowing it much, so it profiles a real ``sc2data rl train`` run in its steady state, which
cProfile (a run of its own, with its overhead) does not::

    py-spy record -p PID -d 60 -r 50 -f raw -o learner.txt --nonblocking
    python benchmarks/profile_shares.py learner.txt --top 40

With ``--idle`` py-spy also samples threads while they wait (the learner waiting for its
workers); other threads' samples (tqdm's monitor, always waiting) are left out by ``--within
FUNCTION``, which keeps only the stacks that hold it (``_train_locked`` for the learner).

A function counts once per sample however deep it recurses, so shares of nested functions add
up along a stack, not across it.
"""

from __future__ import annotations

import argparse
import collections
import re
from pathlib import Path

_FRAME = re.compile(r"(?P<name>.*) \((?P<file>[^:()]*)(?::\d+)?\)$")


def shares(path: Path, within: str | None = None) -> tuple[int, collections.Counter[str]]:
    """The number of samples (those whose stack holds a function named ``within``, if given)
    and, per ``function file``, how many hold it in their stack."""
    total, held = 0, collections.Counter[str]()
    for line in path.read_text().splitlines():
        if not line.strip():
            continue
        stack, count = line.rsplit(" ", 1)
        n = int(count)
        names = set()
        for frame in stack.split(";"):
            m = _FRAME.match(frame)
            names.add(f"{m['name']} {Path(m['file']).name}" if m else frame)
        if within is not None and not any(name.split(" ")[0] == within for name in names):
            continue
        total += n
        for name in names:
            held[name] += n
    return total, held


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("profile", type=Path, help="py-spy record -f raw output")
    ap.add_argument("--top", type=int, default=40, help="functions to print")
    ap.add_argument("--within", help="only the samples whose stack holds this function")
    a = ap.parse_args()
    total, held = shares(a.profile, a.within)
    print(f"{total} samples")
    for name, n in held.most_common(a.top):
        print(f"{100 * n / total:5.1f} %  {name}")


if __name__ == "__main__":
    main()
