"""Commands in other words: LSTM vs sentence encoder, without and with training phrasings.

One labelled rollout, two pair sets drawn from it with the same seed — ``base.toml`` (canonical
texts only) and ``phrasings.toml`` (the same recipe with training phrasings; identical states,
splits, kinds and command ids, only the train split's texts differ) — and four runs on the same
settings. Every run is evaluated on the same held-out paraphrases, and on the training
phrasings given as ``--text`` (unseen by the base runs, seen by the others). Prints the table of
BENCHMARKS.md, "Phrasings", and the exact commands it ran.

    python benchmarks/bench_phrasing.py --out /tmp/phrasing            # everything, ~30 min
    python benchmarks/bench_phrasing.py --out /tmp/phrasing --epochs 10 --only lstm-base
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
    a = ap.parse_args()
    out: Path = a.out
    out.mkdir(parents=True, exist_ok=True)
    log = out / "bench.log"
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    sh([*SC2DATA, "build", str(HERE / "base.toml"), "--out", str(out / "data"), "--workers", "2",
        "--no-progress"], log)
    pairs = {"base": out / "data" / "pairs", "train": out / "pairs-train"}
    sh([*SC2DATA, "pair", str(HERE / "phrasings.toml"), "--data", str(out / "data" / "rollout"),
        "--out", str(pairs["train"]), "--no-progress"], log)
    from sc2data.recipe import load

    train_phrases = [f"{p}={c.id}" for c in load(HERE / "phrasings.toml").commands
                     for p in c.train_paraphrases]
    rows = []
    for name in a.only:
        encoder, pairset = RUNS[name]
        run = out / "runs" / name
        seconds = sh([*SC2DATA, "train", str(pairs[pairset]), "--out", str(run), "--overwrite",
                      "--text-encoder", encoder, "--epochs", str(a.epochs), "--threads",
                      str(a.threads), "--no-progress"], log)
        sh([*SC2DATA, "evaluate", str(run), "--device", "cpu",
            *[x for t in train_phrases for x in ("--text", t)]], log)
        report = json.loads((run / "eval.json").read_text())
        metrics = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
        test = report["splits"]["test"]
        ph = test["phrasings"]
        rows.append((name, test["accuracy"], ph["held_out"]["mean_balanced_accuracy"],
                     ph["held_out"]["worst"], ph["extra"]["mean_balanced_accuracy"],
                     ph["extra"]["worst"], seconds,
                     sum(m["seconds"] + m["val_seconds"] for m in metrics) / len(metrics),
                     max(m["epoch"] for m in metrics if m["best"])))
    pct = lambda x: f"{100 * x:.2f}"  # noqa: E731
    print(f"\nmachine: {platform.platform()}, {os.cpu_count()} CPUs; epochs {a.epochs}, "
          f"threads {a.threads}")
    print("| run | test accuracy % (canonical) | held-out paraphrases, mean balanced % | worst "
          "held-out | training phrasings, mean balanced % | worst training phrasing | train "
          "wall s | s / epoch | best epoch |")
    print("| --- | ---: | ---: | --- | ---: | --- | ---: | ---: | ---: |")
    for name, acc, hm, hw, tm, tw, secs, per_epoch, best in rows:
        print(f"| {name} | {pct(acc)} | {pct(hm)} | {hw['text']!r} {pct(hw['balanced_accuracy'])}"
              f" | {pct(tm)} | {tw['text']!r} {pct(tw['balanced_accuracy'])} | {secs:.0f} | "
              f"{per_epoch:.1f} | {best} |")


if __name__ == "__main__":
    main()
