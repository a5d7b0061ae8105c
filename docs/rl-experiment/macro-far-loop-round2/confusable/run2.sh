#!/bin/bash
# Issue 27: round 2's far-site pairs with multi_match, mem-loopc fine-tuned 3 epochs with mismatches
# at D and (optionally) the confused depot/barracks mismatches at C; agreement on 5 learners.
# Code: /work/exp/tree5 (12ec69f, --confusable-distance). Usage: run.sh NAME D [C]. Resumable.
cd /work/exp/tree5
export PYTHONPATH=/work/exp/tree5
S="nice -n 5 /work/main/.venv/bin/python -m sc2data.cli"
O=/work/exp/loope; N=$1; D=$2; C=$3
[ -f $O/pairs/pairs.done ] || { $S pair $O/loop-round2-multi.toml --data /work/exp/loopd/data --out $O/pairs && touch $O/pairs/pairs.done; } || exit 1
[ -f $O/$N/eval.json ] || { $S train $O/pairs --init /work/exp/loopc/mem --epochs 3 --threads 1 --mismatch-distance $D ${C:+--confusable-distance $C} --out $O/$N --no-progress && $S evaluate $O/$N --no-progress; } || exit 1
for r in /work/exp/narr-clip-arm/macro/macro-narration-s3 /work/exp/narr-clip-arm/macro/macro-narration-s4 /work/exp/bcinit/sparse-s0 /work/exp/narr-clip-arm/macro/macro-narration-s1 /work/exp/narr-clip-arm/macro/macro-narration-s2; do
  n=$(basename $r)
  [ -f $O/agree-$N-$n.json ] || $S rl agreement $r --mem $O/$N --episodes 3 --out $O/agree-$N-$n.json
done
