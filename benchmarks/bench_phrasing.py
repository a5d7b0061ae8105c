"""Commands in other words: LSTM vs sentence encoder, without and with training phrasings.

One labelled rollout, two pair sets drawn from it with the same seed — ``base.toml`` (canonical
texts only) and ``phrasings.toml`` (the same recipe with training phrasings; identical states,
splits, kinds and command ids, only the train split's texts differ) — and four runs on the same
settings. Every run is evaluated on the same held-out paraphrases, and on the training
phrasings given as ``--text`` (unseen by the base runs, seen by the others). Prints the table of
BENCHMARKS.md, "Phrasings", and the exact commands it ran.

    python benchmarks/bench_phrasing.py --out /tmp/phrasing            # everything, ~30 min
    python benchmarks/bench_phrasing.py --out /tmp/phrasing --epochs 10 --only lstm-base
    python benchmarks/bench_phrasing.py --table /tmp/phrasing/runs/*   # the table alone
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent / "phrasing"
SC2DATA = [sys.executable, "-m", "sc2data.cli"]
RUNS = {"lstm-base": ("lstm", "base"), "lstm-train": ("lstm", "train"),
        "minilm-base": ("minilm", "base"), "minilm-train": ("minilm", "train")}


def sh(args: list[str], log: Path) -> float:
    """Run one command (echoed, output to ``log``); its wall seconds."""
    print("$", shlex.join(["sc2data", *args[len(SC2DATA):]] if args[:3] == SC2DATA else args),
          flush=True)
    t0 = time.perf_counter()
    with open(log, "a") as f:
        subprocess.run(args, check=True, stdout=f, stderr=subprocess.STDOUT)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/tmp/phrasing"))
    ap.add_argument("--epochs", type=int, default=10)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--only", nargs="*", default=list(RUNS), choices=list(RUNS))
    ap.add_argument("--runs", default="runs", help="Run folders go to OUT/RUNS/<run>.")
    ap.add_argument("--table", nargs="*", metavar="RUN", help="Only print the table of these run "
                    "folders (already trained and evaluated).")
    a = ap.parse_args()
    if a.table:
        print(table({Path(r).name: Path(r) for r in a.table}))
        return
    out: Path = a.out
    out.mkdir(parents=True, exist_ok=True)
    log = out / "bench.log"
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    sh([*SC2DATA, "build", str(HERE / "base.toml"), "--out", str(out / "data"), "--workers", "2",
        "--no-progress"], log)
    pairs = {"base": out / "data" / "pairs", "train": out / "pairs-train"}
    sh([*SC2DATA, "pair", str(HERE / "phrasings.toml"), "--data", str(out / "data" / "rollout"),
        "--out", str(pairs["train"]), "--no-progress"], log)
    from sc2data.ground.recipe import load

    train_phrases = [f"{p}={c.id}" for c in load(HERE / "phrasings.toml").commands
                     for p in c.train_paraphrases]
    runs = {}
    for name in a.only:
        encoder, pairset = RUNS[name]
        run = runs[name] = out / a.runs / name
        sh([*SC2DATA, "train", str(pairs[pairset]), "--out", str(run), "--overwrite",
            "--text-encoder", encoder, "--epochs", str(a.epochs), "--threads", str(a.threads),
            "--no-progress"], log)
        sh([*SC2DATA, "evaluate", str(run), "--device", "cpu",
            *[x for t in train_phrases for x in ("--text", t)]], log)
    print(f"\nmachine: {platform.platform()}, {os.cpu_count()} CPUs; epochs {a.epochs}, "
          f"threads {a.threads}")
    print(table(runs))


def table(runs: dict[str, Path]) -> str:
    """The BENCHMARKS.md table from the runs' eval.json and metrics.jsonl."""
    pct = lambda x: f"{100 * x:.2f}"  # noqa: E731
    lines = ["| run | test accuracy % (canonical) | held-out paraphrases: mean balanced % | worst "
             "held-out | training phrasings: mean balanced % | worst training phrasing | "
             "training s (train + val, all epochs) | best epoch |",
             "| --- | ---: | ---: | --- | ---: | --- | ---: | ---: |"]
    for name, run in runs.items():
        test = json.loads((run / "eval.json").read_text())["splits"]["test"]
        metrics = [json.loads(x) for x in (run / "metrics.jsonl").read_text().splitlines()]
        held, seen = test["phrasings"]["held_out"], test["phrasings"]["extra"]
        lines.append(
            f"| {name} | {pct(test['accuracy'])} | {pct(held['mean_balanced_accuracy'])} | "
            f"{held['worst']['text']!r} {pct(held['worst']['balanced_accuracy'])} | "
            f"{pct(seen['mean_balanced_accuracy'])} | {seen['worst']['text']!r} "
            f"{pct(seen['worst']['balanced_accuracy'])} | "
            f"{sum(m['seconds'] + m['val_seconds'] for m in metrics):.0f} | "
            f"{max(m['epoch'] for m in metrics if m['best'])} |")
    return "\n".join(lines)

if __name__ == "__main__":
    main()
