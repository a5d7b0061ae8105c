#!/bin/bash
# Each MEM on round 2's own pair set (no multi_match): test accuracy and held-out paraphrases comparable with loopd's.
cd /work/exp/tree5; export PYTHONPATH=/work/exp/tree5
for n in c10 d08 c85 c10x; do
  ls /work/exp/loope/$n/eval-*.json >/dev/null 2>&1 || nice -n 5 /work/main/.venv/bin/python -m sc2data.cli evaluate /work/exp/loope/$n --data /work/exp/loopd/pairs --other-data --no-progress
done
