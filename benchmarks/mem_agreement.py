"""A MEM against the labelling rules on every stack of a labelled rollout (offline agreement).

`sc2data rl agreement` plays a policy live and judges the stacks it passes through; this reads a
rollout already made and labelled (`sc2data rollout --agent policy:RUN …; sc2data label DATA`),
so several MEMs are judged on the very same stacks, as many as the rollout holds. Per command of
the MEM's pair set: the rule's firings, the MEM's matches (distance < the model's threshold),
precision, recall, and what the false matches were (`sc2data.rl.agreement.false_matches`: the
stacks where another command's rule fired, or none did); and how many null stacks the MEM
matched to some command; and recall on the stacks where no other rule fired (a stack where two
rules fire, say an idle SCV sent to mine as a depot appears, is one the pair sets rarely hold).
With ``--by-action``, also each command's firings split by the pysc2
function the agent called in that step, and the MEM's matches among them: a rule that reads two
frames cannot always tell what the step did (``collect_minerals`` fires when an idle SCV is sent
to build as well as to mine), and this shows where the rule, not the MEM, is the one wrong.

    python benchmarks/mem_agreement.py RUN [RUN2 …] DATA [--out FILE.json] [--by-action]
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
from pysc2.lib import actions as sc2_actions

import sc2data
from sc2data.rl.agreement import by_action, false_matches, recall_alone

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
    function = np.zeros(len(fired), dtype=object)
    ds = sc2data.open_dataset(data)
    for episodes, steps, batch in ds.iter_batches(BATCH):
        at = np.array([row[(int(e), int(s))] for e, s in zip(episodes, steps)])
        matched[at] = mem.distances(batch, texts) < mem.threshold
        function[at] = [sc2_actions.FUNCTIONS[int(f)].name
                        for f in ds.actions(episodes, steps)["function"]]
    tp = (fired & matched).sum(0)
    n_alone, r_alone = recall_alone(fired, matched)
    confused = false_matches(fired, matched, ids)
    per = {}
    for k, cid in enumerate(ids):
        n_f, n_m = int(fired[:, k].sum()), int(matched[:, k].sum())
        per[cid] = {"rule_fired": n_f, "mem_matched": n_m, "tp": int(tp[k]),
                    "precision": round(100 * tp[k] / n_m, 2) if n_m else None,
                    "recall": round(100 * tp[k] / n_f, 2) if n_f else None,
                    "fired_alone": int(n_alone[k]),
                    "recall_alone": None if r_alone[k] is None else round(100 * r_alone[k], 2),
                    "false_matches": confused[cid],
                    "by_action": by_action(fired[:, k], matched[:, k], function)}
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
    ap.add_argument("--by-action", action="store_true",
                    help="also print each command's firings by the step's pysc2 function")
    args = ap.parse_args(argv)
    results = [judge(run, args.data) for run in args.runs]
    print(f"{args.data}: {results[0]['stacks']:,} stacks, {results[0]['episodes']} episodes\n")
    print(table(results))
    for r in results:
        for cid, c in r["commands"].items():
            if c["false_matches"]:
                print(f"{Path(r['mem']).name} {cid} false matches: {c['false_matches']}")
    for r in results:
        print(f"{Path(r['mem']).name} recall where no other rule fired: " + ", ".join(
            f"{cid} {c['recall_alone']} ({c['fired_alone']})" for cid, c in r["commands"].items()))
    if args.by_action:
        for r in results:
            for cid, c in r["commands"].items():
                parts = [f"{name} {v['matched']}/{v['fired']}"
                         for name, v in c["by_action"].items()]
                print(f"{Path(r['mem']).name} {cid} matched / fired by action: "
                      + ", ".join(parts))
    if args.out:
        args.out.write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
