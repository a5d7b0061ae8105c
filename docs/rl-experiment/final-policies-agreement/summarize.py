"""Summarise `sc2data rl agreement` JSONs (one per final policy): the MEM against the rules and
both against the simulator's record, one row a policy, then pooled per action space and command.
Usage: python summarize.py AGREEMENT.json ..."""

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


def pooled(paths: list[str]) -> None:
    """Per action space and command, counts summed over the policies: the MEM against the rules
    (precision, recall, recall where only its rule fired) and the rule and the MEM against the
    game's record."""
    keys = ("tp", "fp", "fn", "alone", "alone_hit", "happened", "rule", "rule_hit", "mem",
            "mem_hit")
    total: dict[tuple[str, str], dict[str, int]] = {}
    for p in paths:
        r = json.loads(Path(p).read_text())
        space = r["config"]["action_space"]
        for cid, c in r["commands"].items():
            t = total.setdefault((space, cid), dict.fromkeys(keys, 0))
            s = c["sim"]
            for k in ("tp", "fp", "fn"):
                t[k] += c[k]
            t["alone"] += c["fired_alone"]
            t["alone_hit"] += round((c["recall_alone"] or 0) * c["fired_alone"])
            t["happened"] += s["happened"]
            t["rule"] += c["rule_fired"]
            t["rule_hit"] += round((s["rule_precision"] or 0) * c["rule_fired"])
            t["mem"] += c["mem_matched"]
            t["mem_hit"] += round((s["mem_precision"] or 0) * c["mem_matched"])

    def ratio(a: int, b: int) -> str:
        return pct(a / b if b else None)

    print("\n| space | command | MEM vs rules P / R / R only rule | happened | rule vs game P / R "
          "| MEM vs game P / R |")
    print("| --- | --- | --- | --- | --- | --- |")
    for (space, cid), t in sorted(total.items()):
        print(f"| {space} | {cid} | {ratio(t['tp'], t['tp'] + t['fp'])} / "
              f"{ratio(t['tp'], t['tp'] + t['fn'])} / {ratio(t['alone_hit'], t['alone'])} | "
              f"{t['happened']:,} (rule fired {t['rule']:,}) | {ratio(t['rule_hit'], t['rule'])} / "
              f"{ratio(t['rule_hit'], t['happened'])} | {ratio(t['mem_hit'], t['mem'])} / "
              f"{ratio(t['mem_hit'], t['happened'])} |")


if __name__ == "__main__":
    main(sys.argv[1:])
    pooled(sys.argv[1:])
