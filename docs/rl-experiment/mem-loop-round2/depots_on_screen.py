"""Diagnostic for BENCHMARKS.md ("The MEM loop, round 2"): on a labelled rollout's depot stacks,
each MEM's distances to "build a supply depot" and "build a barracks", binned by the depots
already on the screen (depot pixels of the stack's first frame / 36, a 2×2 depot covering about
36 pixels), and the share it also matches as a barracks.

    python depots_on_screen.py DATA RUN [RUN …]
"""

import sys

import numpy as np
import pyarrow.parquet as pq

import sc2data

DEPOT = 19  # pysc2 units.Terran.SupplyDepot
BINS = [(0, 5), (5, 10), (10, 20), (20, 99)]

root, runs = sys.argv[1], sys.argv[2:]
ds = sc2data.open_dataset(root)
lab = pq.read_table(f"{root}/labels.parquet").to_pandas()
sel = lab[lab.rule_id == "build_supply_depot"]
stacks = [ds[int(e), int(s)] for e, s in zip(sel.episode, sel.step)]
on_screen = np.array([(b.layer("screen/unit_type")[0][0] == DEPOT).sum() / 36.0 for b in stacks])
for run in runs:
    mem = sc2data.load_model(run)
    d = np.array([mem.distances(b, ["build a supply depot", "build a barracks"])[0]
                  for b in stacks])
    cells = []
    for lo, hi in BINS:
        m = (on_screen >= lo) & (on_screen < hi)
        if m.any():
            also = 100 * (d[m, 1] < 0.5).mean()
            cells.append(f"{lo}-{hi} depots: n={m.sum()} d(depot) {d[m, 0].mean():.2f} "
                         f"d(barracks) {d[m, 1].mean():.2f} also barracks {also:.0f}%")
    print(run.rstrip("/").split("/")[-1], "|", " ; ".join(cells))
