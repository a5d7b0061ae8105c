#!/bin/bash
# PPO from scratch, paper space, sparse, 100,352 decisions (the grid's settings), cell or pixel point head
# usage: SEEDS="0 1" seeds.sh HEAD OUTDIR
cd ${WT:-/work/main}
PY=/work/main/.venv/bin/python
head=$1; D=$2; mkdir -p $D
for s in ${SEEDS:-0 1 2 3 4}; do
  out=$D/$head-s$s
  [ -f $out/eval.json ] && continue
  nice -n 5 $PY -m sc2data.cli rl train --out $out --action-space paper --reward sparse --steps 100352 --point-head $head --threads 1 --no-progress --seed $s >> $D/$head.log 2>&1 && \
  nice -n 5 $PY -m sc2data.cli rl evaluate $out --episodes 10 --no-progress --processes 1 >> $D/$head.log 2>&1
done
