#!/bin/bash
# issue 27: mismatch distance 0.9 with multi_match (mem-2m9), as mem-2md otherwise
while pgrep -f distance.sh >/dev/null; do sleep 10; done
cd /work/paper/loop2
SC=/work/main/.venv/bin/sc2data
PY=/work/main/.venv/bin/python
[ -f mem-2m9/state.json ] && grep -q '"finished": true' mem-2m9/state.json || \
  /usr/bin/time -f "%e s" $SC train pairs-2m --init mem-1c --epochs 3 --threads 1 --mismatch-distance 0.9 --out mem-2m9 --no-progress > train-2m9.log 2>&1
for d in data/h-mem0-s1 data/h-mem1c-s1 data/h-demo-s7 data/h-demo-s4 /work/paper/loop/data/heldout-narration /work/paper/loop/data/heldout-sparse /work/paper/loop/data/heldout-macro-narration; do
  n=$(basename $d)
  [ -f agree-9-$n.json ] || $PY /work/main/benchmarks/mem_agreement.py mem-2 mem-2md mem-2m9 $d --by-action --out agree-9-$n.json > agree-9-$n.txt 2>&1
  echo "$(date +%T) done $n"
done
[ -f eval-mem-2m9-paper.txt ] || $SC evaluate mem-2m9 --data /work/paper/data/pairs --other-data > eval-mem-2m9-paper.txt 2>&1
echo ALLDONE
