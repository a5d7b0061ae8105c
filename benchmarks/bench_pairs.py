"""Benchmark the pair stage: drawing the paper's 150k pairs, and packing stacks.

1. ``build_pairs`` on labels shaped like the paper recipe's data (2,400 reduced-random episodes of
   1,800 steps, each command firing at the rate measured on the simulator), timed end to end.
2. Packing: ``sc2data.pairs.pairset._pack_split`` copying a pair set's stacks from a real
   rolled-out,
   labelled dataset (``--data``, e.g. the demo's ``demo-out/data/rollout``) into a packed file.

    python benchmarks/bench_pairs.py --data demo-out/data/rollout --repeats 3
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa

from sc2data.ground.recipe import load
from sc2data.pairs.draw import Labelled, build_pairs

ROOT = Path(__file__).resolve().parents[1]
# Fire rates per stack measured on 20 reduced-random episodes (smoke recipe, seed 0).
RATES = {"build_scv": 0.0226, "collect_minerals": 0.0097, "build_supply_depot": 0.0071,
         "build_barracks": 0.0024, "train_marine": 0.0301}


def bench_build_pairs(repeats: int) -> None:
    recipe = load(ROOT / "manifests" / "buildmarines-paper.toml")
    episodes, steps = recipe.rollout.episodes, 1800
    rng = np.random.default_rng(0)
    fires = rng.random((episodes * steps, len(recipe.commands))) < \
        np.array([RATES[c.id] for c in recipe.commands])
    data = Labelled(np.repeat(np.arange(episodes), steps),
                    np.tile(np.arange(steps, dtype=np.int32), episodes), fires)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        table = build_pairs(recipe, data)
        times.append(time.perf_counter() - t)
    print(f"build_pairs, paper recipe ({len(fires):,} stacks → {table.num_rows:,} pairs): "
          f"median {statistics.median(times):.2f} s over {repeats}")


def bench_pack(data: Path, repeats: int, n: int) -> None:
    from sc2data.data.dataset import open_dataset
    from sc2data.pairs.pairset import _pack_split

    ds = open_dataset(data)
    rng = np.random.default_rng(1)
    pos = rng.choice(len(ds), size=min(n, len(ds)), replace=False)
    episodes, steps = ds.locate_positions(pos)
    pairs = pa.table({"episode": pa.array(episodes, pa.int64()),
                      "step": pa.array(steps, pa.int32())})

    class Quiet:
        def update(self, k: int) -> None:
            pass

    rates = []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            _, states = _pack_split(ds, "train", pairs, Path(tmp) / "train.h5", 0, Quiet())
            rates.append(states / (time.perf_counter() - t))
    print(f"packing {states:,} random stacks of {len(ds):,} ({ds.schema.to_dict()['screen'][0]}…, "
          f"{len(ds.schema.keys())} keys): median {statistics.median(rates):,.0f} stacks/s; "
          f"the paper's ~100k states would take ≈ {100_000 / statistics.median(rates):.0f} s")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, help="a rolled-out dataset folder, for packing")
    p.add_argument("--stacks", type=int, default=4000, help="stacks to pack")
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args()
    bench_build_pairs(a.repeats)
    if a.data:
        bench_pack(a.data, a.repeats, a.stacks)


if __name__ == "__main__":
    main()
