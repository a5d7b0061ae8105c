#!/bin/bash
# The MEM loop, round 2: the clone-started learners' states (issue 27)
cd /work/main
PY="nice -n 10 /work/main/.venv/bin/python -m sc2data.cli"
L=/work/exp/loop2
for r in sparse-s1 narrpot-s1; do
  d=$L/data/kick-$r
  [ -f $d/labels.parquet ] || { $PY rollout --agent policy:/work/exp/kick/seeds/$r --episodes 120 --workers 1 --layers paper --out $d --no-progress && $PY label $d --no-progress; } || exit 1
done
[ -f $L/pairs/pairset.json ] || $PY pair $L/loop-round2.toml --data $L/data --out $L/pairs --no-progress || exit 1
[ -f $L/mem/best.pt ] || $PY train $L/pairs --init /work/exp/loop-grid/mem --epochs 3 --threads 1 --out $L/mem --no-progress || exit 1
$PY evaluate $L/mem --no-progress > $L/eval-own.txt 2>&1
$PY evaluate $L/mem --data /work/exp/paper-data/pairs --other-data --no-progress > $L/eval-paper.txt 2>&1
for r in kick/sparse-c1 kick/narrpot-c1 kick/seeds/sparse-s1 kick/seeds/narrpot-s1 grid1m/paper/paper-narration-s0 grid1m/paper/paper-narration-s1 grid1m/paper/paper-sparse-s0 grid1m/paper/paper-sparse-s1; do
  n=$(echo $r | tr '/' '-')
  $PY rl agreement /work/exp/$r --mem $L/mem --episodes 3 --out $L/agree-$n.json --no-progress > $L/agree-$n.txt 2>&1
done
for r in kick/seeds/sparse-s1 kick/seeds/narrpot-s1; do
  n=$(echo $r | tr '/' '-')
  $PY rl agreement /work/exp/$r --mem /work/exp/loop-grid/mem --episodes 3 --out $L/agree-round1-$n.json --no-progress > $L/agree-round1-$n.txt 2>&1
done
echo done
