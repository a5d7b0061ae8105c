"""A MEM against the labelling rules on every stack of a labelled rollout (offline agreement).

`sc2data rl agreement` plays a policy live and judges the stacks it passes through; this reads a
rollout already made and labelled (`sc2data rollout --agent policy:RUN …; sc2data label DATA`),
so several MEMs are judged on the very same stacks, as many as the rollout holds. Per command of
the MEM's pair set: the rule's firings, the MEM's matches (distance < the model's threshold),
precision, recall, and what the false matches were (`sc2data.rl.agreement.false_matches`: the
stacks where another command's rule fired, or none did); and how many null stacks the MEM
matched to some command.

    python benchmarks/mem_agreement.py RUN DATA [RUN2 …] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq

import sc2data
from sc2data.rl.agreement import false_matches

BATCH = 2048
"""Stacks read and scored at once."""


def judge(run: Path, data: Path) -> dict[str, Any]:
    """Agreement of the MEM in ``run`` with the rules on every labelled stack of ``data``."""
    mem = sc2data.load_model(run, threads=1)
    commands = [c for c in mem.commands if c.get("id") and c.get("text")]
    ids, texts = [str(c["id"]) for c in commands], [str(c["text"]) for c in commands]
    labels = pq.read_table(data / "stack_labels.parquet").to_pandas()
    missing = [i for i in ids if i not in labels.columns]
    if missing:
        sys.exit(f"{data} has no labels for {', '.join(missing)}; label it with those rules")
    row = {(int(e), int(s)): k for k, (e, s) in enumerate(zip(labels.episode, labels.step))}
    fired = labels[ids].to_numpy(bool)
    matched = np.zeros_like(fired)
    for episodes, steps, batch in sc2data.open_dataset(data).iter_batches(BATCH):
        at = np.array([row[(int(e), int(s))] for e, s in zip(episodes, steps)])
        matched[at] = mem.distances(batch, texts) < mem.threshold
    tp = (fired & matched).sum(0)
    confused = false_matches(fired, matched, ids)
    per = {}
    for k, cid in enumerate(ids):
        n_f, n_m = int(fired[:, k].sum()), int(matched[:, k].sum())
        per[cid] = {"rule_fired": n_f, "mem_matched": n_m, "tp": int(tp[k]),
                    "precision": round(100 * tp[k] / n_m, 2) if n_m else None,
                    "recall": round(100 * tp[k] / n_f, 2) if n_f else None,
                    "false_matches": confused[cid]}
    null = ~fired.any(1)
    return {"mem": str(run), "data": str(data), "stacks": int(len(fired)),
            "episodes": int(labels.episode.nunique()), "threshold": mem.threshold,
            "commands": per, "null_stacks": int(null.sum()),
            "null_matched": int((null & matched.any(1)).sum())}


def table(results: Sequence[dict[str, Any]]) -> str:
    """Markdown: a row per command, precision / recall of each MEM side by side."""
    head = "| command | rule fired | " + " | ".join(
        f"{Path(r['mem']).name}: P / R" for r in results) + " |"
    lines = [head, "| --- | ---: |" + " --- |" * len(results)]
    for cid, c in results[0]["commands"].items():
        cells = [f"{r['commands'][cid]['precision']} / {r['commands'][cid]['recall']}"
                 for r in results]
        lines.append(f"| {cid} | {c['rule_fired']:,} | " + " | ".join(cells) + " |")
    lines.append("| null stacks matched | " + f"{results[0]['null_stacks']:,} | " + " | ".join(
        f"{r['null_matched']:,}" for r in results) + " |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path, help="MEM runs (sc2data train --out)")
    ap.add_argument("data", type=Path, help="a labelled rollout (sc2data label DATA)")
    ap.add_argument("--out", type=Path, help="JSON file for the results")
    args = ap.parse_args(argv)
    results = [judge(run, args.data) for run in args.runs]
    print(f"{args.data}: {results[0]['stacks']:,} stacks, {results[0]['episodes']} episodes\n")
    print(table(results))
    for r in results:
        for cid, c in r["commands"].items():
            if c["false_matches"]:
                print(f"{Path(r['mem']).name} {cid} false matches: {c['false_matches']}")
    if args.out:
        args.out.write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
