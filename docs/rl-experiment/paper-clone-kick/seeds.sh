#!/bin/bash
# PPO held near a clone (--init-policy + --kickstart, C = $COEF, default 1), 100,352 decisions, seeds $SEEDS, arm $1
# usage: seeds.sh ARM CLONE OUTDIR   (ARM: sparse | narrpot | narrloop; $EXTRA: more rl train
# options, e.g. EXTRA="--point-head pixel" for ../paper-pixel-head/kick/; $WT: the checkout to run)
cd ${WT:-/work/main}
PY=/work/main/.venv/bin/python
arm=$1; C=$2; D=$3; mkdir -p $D
COMMON="--action-space paper --history --init-policy $C --kickstart $C --kickstart-coef ${COEF:-1} --steps 100352 --no-progress --threads 1 --target-kl 0.05 $EXTRA"
case $arm in
  sparse) R="--reward sparse";;
  narrpot) R="--reward narration --mem /work/exp/paper-mem --shaping potential";;
  narrloop) R="--reward narration --mem /work/exp/loop2/mem --shaping potential";;  # MEM loop round 2
esac
for s in ${SEEDS:-0 1 2 3 4 5 6 7 8 9}; do
  out=$D/$arm-s$s
  [ -f $out/eval.json ] && continue
  nice -n 5 $PY -m sc2data.cli rl train --out $out $COMMON $R --seed $s >> $D/$arm.log 2>&1 && \
  nice -n 5 $PY -m sc2data.cli rl evaluate $out --episodes 10 --no-progress --processes 1 >> $D/$arm.log 2>&1
done
