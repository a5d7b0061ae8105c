#!/bin/bash
# issue 27: every final policy of the experiment judged with the loop's MEM (mem-2), 3 episodes,
# rules and MEM also against the simulator's record. Resumable: existing JSONs are skipped.
cd /work/main
SC=/work/main/.venv/bin/sc2data
O=/work/exp/agree-final
runs="1m/paper-narration-s0 1m/paper-sparse-s0 macro-200k/macro/macro-narration-s0 macro-200k/macro/macro-sparse-s0"
for s in 0 1 2 3 4 5 6 7 8 9; do runs="$runs p100k-mem2/paper/paper-narration-s$s"; done
for s in 0 1 2 3 4 5 6 7 8 9; do runs="$runs pilot/paper/paper-sparse-s$s"; done
for s in 0 1 2 3 4; do runs="$runs p100k-rules-pot/paper/paper-rules-s$s p100k-mem2-para/paper/paper-narration-s$s"; done
for r in $runs; do
  name=$(echo $r | tr / _)
  [ -f $O/$name.json ] && continue
  nice -n 5 $SC rl agreement /work/exp/$r --mem /work/paper/loop2/mem-2 --episodes 3 --out $O/$name.json > $O/$name.txt 2>&1
  echo "$(date +%T) $name $?"
done
echo ALLDONE
