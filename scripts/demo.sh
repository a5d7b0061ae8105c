#!/usr/bin/env bash
# `make demo`: the smoke recipe end to end on the embedded simulator —
# rollout → label → pair (sc2data build), then train → evaluate → t-SNE.
set -euo pipefail
OUT=${1:-demo-out}
SC2DATA=${SC2DATA:-.venv/bin/sc2data}
"$SC2DATA" build manifests/smoke.toml --out "$OUT/data"
"$SC2DATA" train "$OUT/data/pairs" --out "$OUT/run" --epochs 5 --overwrite
"$SC2DATA" evaluate "$OUT/run"
"$SC2DATA" tsne "$OUT/run" --out "$OUT/tsne.png"
echo "t-SNE picture: $OUT/tsne.png"
