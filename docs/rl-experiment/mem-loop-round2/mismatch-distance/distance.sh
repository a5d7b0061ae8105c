#!/bin/bash
# issue 27: the mismatch distance 0.8 (room for two-rule states), round 2's pairs with and without
# multi_match, fine-tuned from mem-1c exactly as mem-2 / mem-2m; then judged on the held-out sets.
cd /work/paper/loop2
SC=/work/main/.venv/bin/sc2data
PY=/work/main/.venv/bin/python
[ -f mem-2md/state.json ] && grep -q '"finished": true' mem-2md/state.json || \
  /usr/bin/time -f "%e s" $SC train pairs-2m --init mem-1c --epochs 3 --threads 1 --mismatch-distance 0.8 --out mem-2md --no-progress > train-2md.log 2>&1
[ -f mem-2d/state.json ] && grep -q '"finished": true' mem-2d/state.json || \
  /usr/bin/time -f "%e s" $SC train pairs-2 --init mem-1c --epochs 3 --threads 1 --mismatch-distance 0.8 --out mem-2d --no-progress > train-2d.log 2>&1
for d in data/h-mem0-s1 data/h-mem1c-s1 data/h-demo-s7 data/h-demo-s4 /work/paper/loop/data/heldout-narration /work/paper/loop/data/heldout-sparse /work/paper/loop/data/heldout-macro-narration; do
  n=$(basename $d)
  [ -f agree-d-$n.json ] || $PY /work/main/benchmarks/mem_agreement.py mem-2 mem-2m mem-2d mem-2md $d --by-action --out agree-d-$n.json > agree-d-$n.txt 2>&1
  echo "$(date +%T) done $n"
done
for m in mem-2d mem-2md; do
  [ -f eval-$m-paper.txt ] || $SC evaluate $m --data /work/paper/data/pairs --other-data > eval-$m-paper.txt 2>&1
  [ -f eval-$m-para.txt ] || $SC evaluate $m > eval-$m-own.txt 2>&1
done
echo ALLDONE
