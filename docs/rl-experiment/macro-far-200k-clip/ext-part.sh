#!/bin/bash
# Issue 26: the far-site clip-opened macro pair (narration, loop MEM round 1; sparse) continued
# from 100,352 to 200,000 decisions, the grid's macro budget. SEEDS as arguments, seed by seed,
# narration then sparse; two instances with disjoint seeds side by side (--threads 1 each).
# Resumable: rerun. The 100k state of both arms is kept in /work/exp/ext200/snap-100k.
cd /work/exp/tree2
TA="--macro-sites far --gamma 0.999 --normalize-advantage --epochs 10 --no-share-features --max-grad-norm 100 --threads 1"
for s in "$@"; do
  PYTHONPATH=/work/exp/tree2 nice -n 5 /work/main/.venv/bin/python benchmarks/rl_experiment.py --out /work/exp/narr-clip-arm \
    --mem /work/exp/loopc/mem --steps macro=200000 --rewards narration --seeds $s --eval-episodes macro=10 --train-args "$TA"
  PYTHONPATH=/work/exp/tree2 nice -n 5 /work/main/.venv/bin/python benchmarks/rl_experiment.py --out /work/exp/sparse-clip-arm \
    --steps macro=200000 --rewards sparse --seeds $s --eval-episodes macro=10 --train-args "$TA"
done
