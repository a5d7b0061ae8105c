"""Training throughput of the MEM with the data loader in the loop, and the loader alone.

Prints, for each torch thread count (CPU) or for the GPU: pairs/s of a real ``sc2data train``
epoch (loader, input packing, forward, backward, Adam — everything but validation) and of the
validation pass, the loader's own pairs/s (block reads + LZ4 decode + shuffle + packing, no
model), and the projected wall time of the paper-size run: 100k train pairs and 25k validation
pairs, 20 epochs. Figures are the median over ``--repeats`` runs; the first epoch of each run is
a warm-up and is not counted.

    python benchmarks/bench_train.py                      # CPU, 1 and 2 threads, synthetic data
    python benchmarks/bench_train.py --data DATA          # a real pair set (sc2data build)
    python benchmarks/bench_train.py --device cuda --amp  # on a GPU machine
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

PAPER_TRAIN, PAPER_VAL, PAPER_EPOCHS = 100_000, 25_000, 20


def loader_alone(data: Path, pool: int, categorical: str, passes: int, gpu: bool) -> float:
    """Pairs/s of a shuffled pass over the train split, as the trainer's loader delivers it
    (packed in numpy for CPU training; raw stacks, pinned if a GPU is present, for GPU
    training, which packs on the device), with no training."""
    import torch

    from sc2data.model import mem as M
    from sc2data.pairs.loader import PairLoader, PairSet

    ps = PairSet(data)
    p = ps.pairs("train")
    packed = ps.packed("train")
    cfg = M.ModelConfig(categorical=categorical, pool=pool)  # type: ignore[arg-type]
    tables = M.value_tables(ps.schema, [packed.read(0, min(len(packed), 1024))], cfg.max_table)
    model = M.MEM(ps.schema, tables, np.zeros((2, 50), np.float32), cfg)
    pin = gpu and torch.cuda.is_available()
    loader = PairLoader(packed, p.state, np.zeros(len(p), np.int64), p.target, batch_size=32,
                        keys=model.state.keys(), shuffle=True,
                        transform=None if gpu else model.state.pack,
                        collate=lambda rows: M.to_tensors(rows, pin=pin))
    rates = []
    for e in range(passes):
        t0, n = time.perf_counter(), 0
        for batch in loader.epoch(e):
            n += len(batch)
        rates.append(n / (time.perf_counter() - t0))
    packed.close()
    return statistics.median(rates)


def training(data: Path, device: str, threads: int | None, amp: bool, pool: int,
             categorical: str, epochs: int) -> tuple[float, float, float]:
    """(train pairs/s, train pairs per CPU-second, validation pairs/s) of ``sc2data train``,
    epochs after the first."""
    from sc2data.model.train import TrainConfig, train
    from sc2data.pairs.loader import PairSet

    with tempfile.TemporaryDirectory() as out:
        run = train(TrainConfig(data=str(data), out=out, epochs=epochs, device=device,
                                threads=threads, amp=amp, pool=pool, categorical=categorical,
                                progress=False, overwrite=True))
        rows = [json.loads(l) for l in (run / "metrics.jsonl").read_text().splitlines()][1:]
    n_val = len(PairSet(data).pairs("val"))
    n_train = len(PairSet(data).pairs("train"))
    return (statistics.median(r["pairs_per_s"] for r in rows),
            statistics.median(n_train / r["cpu_seconds"] for r in rows),
            statistics.median(n_val / r["val_seconds"] for r in rows))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, help="pair-set folder [default: a synthetic one]")
    ap.add_argument("--states", type=int, default=500, help="synthetic states per command")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--threads", default="1,2", help="torch CPU thread counts to try")
    ap.add_argument("--amp", action="store_true")
    ap.add_argument("--pool", type=int, default=2)
    ap.add_argument("--categorical", default="onehot")
    ap.add_argument("--epochs", type=int, default=3, help="per run; the first is a warm-up")
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()

    tmp = None
    data = args.data
    if data is None:
        from sc2data.testing.synthetic_pairs import write_pairset

        tmp = tempfile.TemporaryDirectory()
        t0 = time.perf_counter()
        data = write_pairset(Path(tmp.name) / "data", states_per_command=args.states,
                             null_states=2 * args.states, episodes=60, seed=0)
        print(f"synthetic pair set: {args.states} states per command, {2 * args.states} null "
              f"({time.perf_counter() - t0:.0f} s to build)")
    meta = json.loads((data / "pairset.json").read_text())
    print(f"data: {data} ({meta['recipe_name']}; splits {meta['splits']})")
    print(f"machine: {platform.platform()}, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.1f}")

    for gpu in (False, True):
        rate = statistics.median(loader_alone(data, args.pool, args.categorical, 2, gpu)
                                 for _ in range(args.repeats))
        what = "raw stacks, as for GPU training" if gpu else "packed, as for CPU training"
        print(f"loader alone (read + decode + shuffle, {what}): {rate:,.0f} pairs/s")
    counts = [None] if args.device != "cpu" else [int(t) for t in args.threads.split(",")]
    for threads in counts:
        runs = [training(data, args.device, threads, args.amp, args.pool, args.categorical,
                         args.epochs) for _ in range(args.repeats)]
        tr = statistics.median(r[0] for r in runs)
        cpu = statistics.median(r[1] for r in runs)
        va = statistics.median(r[2] for r in runs)
        hours = PAPER_EPOCHS * (PAPER_TRAIN / tr + PAPER_VAL / va) / 3600
        label = f"{args.device}" + (f", {threads} thread(s)" if threads else "") + \
            (", amp" if args.amp else "")
        print(f"train {label}: {tr:,.0f} pairs/s with the loader in the loop ({cpu:,.0f} per "
              f"CPU-second of the process), validation {va:,.0f} pairs/s → paper-size run "
              f"(100k × 20 epochs + validation) ≈ {hours * 60:,.0f} min")
    if tmp is not None:
        tmp.cleanup()


if __name__ == "__main__":
    main()
