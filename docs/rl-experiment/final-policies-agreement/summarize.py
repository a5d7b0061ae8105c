"""Summarise `sc2data rl agreement` JSONs (one per final policy): the MEM against the rules and
both against the simulator's record. Usage: python summarize.py AGREEMENT.json ..."""

from __future__ import annotations

import json
import sys
from pathlib import Path


def pct(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.1f}"


def low(values: list[tuple[str, float | None]]) -> str:
    """The lowest of (command, value), as 'value (command)'."""
    known = [(v, c) for c, v in values if v is not None]
    if not known:
        return "–"
    v, c = min(known)
    return f"{pct(v)} ({c.replace('build_', '').replace('train_', '').replace('_', ' ')})"


def main(paths: list[str]) -> None:
    print("| policy | marines | lowest precision vs rules | lowest recall vs rules | lowest "
          "recall, only rule | minerals: happened / rule fired / rule P / MEM P / MEM R vs game "
          "| other commands: lowest rule P·R, MEM P·R vs game |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for p in paths:
        r = json.loads(Path(p).read_text())
        c = r["commands"]
        prec = [(k, v["precision"]) for k, v in c.items()]
        rec = [(k, v["recall"]) for k, v in c.items()]
        alone = [(k, v["recall_alone"]) for k, v in c.items()]
        m = c["collect_minerals"]
        s = m["sim"]
        others = {k: v["sim"] for k, v in c.items() if k != "collect_minerals" and v["sim"]}
        rule = min([x for o in others.values() for x in (o["rule_precision"], o["rule_recall"])
                    if x is not None], default=None)
        mem = min([x for o in others.values() for x in (o["mem_precision"], o["mem_recall"])
                   if x is not None], default=None)
        name = Path(p).stem
        print(f"| {name} | {sum(r['marines']) / len(r['marines']):.1f} | {low(prec)} | "
              f"{low(rec)} | {low(alone)} | {s['happened']} / {m['rule_fired']} / "
              f"{pct(s['rule_precision'])} / {pct(s['mem_precision'])} / {pct(s['mem_recall'])} | "
              f"{pct(rule)}, "
              f"{pct(mem)} |")


if __name__ == "__main__":
    main(sys.argv[1:])
