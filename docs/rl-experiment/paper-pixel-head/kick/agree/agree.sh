#!/bin/bash
# rl agreement on the pixel-head kicked learners: paper MEM (round 0) and the loop's round-2 MEM
# usage: agree.sh RUN:MEM ...   e.g. narrpot-s0:/work/exp/paper-mem narrpot-s0:/work/exp/loop2/mem
# (the paper MEM's files, named -by-exp-paper-mem by this script, are -by-paper-mem here)
cd ${WT:-/work/main}
PY="nice -n 15 /work/main/.venv/bin/python -m sc2data.cli"
K=/work/exp/kickpix
for job in "$@"; do
  run=${job%%:*}; mem=${job##*:}
  name=$K/agree/$run-by-$(basename $(dirname $mem))-$(basename $mem)
  [ -f $name.json ] || $PY rl agreement $K/$run --mem $mem --episodes 3 --out $name.json --no-progress > $name.txt 2>&1
done
