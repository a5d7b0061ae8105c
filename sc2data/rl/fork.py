"""``sc2data rl fork``: a trained run's copy that trains on with another MEM.

The MEM loop (``docs/mem-loop.md``) retrains the MEM on the agent's own states, then continues
the agent's training with the new MEM. A run resumes only with the settings it was trained with
(:func:`sc2data.rl.train.train`), and the MEM is one of them — rightly: a learning curve made
with two rewards is not one run. A fork is a new run folder holding the original's checkpoint,
its trained steps and its curve so far, whose ``config.json`` names the new MEM (and records the
run and MEM it came from in ``fork.json``); ``sc2data rl train --out FORK --mem NEW …`` with the
original's other options and a larger ``--steps`` then resumes it, its episodes seeded as any
resume's (``seed + 1000·resumes``), never repeating the original's.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import sha256_file, write_atomic
from sc2data.rl.runs import CONFIG, CURVE_CSV, CURVE_JSON, MODEL, STATE, new_folder

COPIED = (MODEL, STATE, CURVE_CSV, CURVE_JSON)


def fork(run: Path, out: Path, mem: Path) -> dict[str, Any]:
    """Copy the narration-rewarded run ``run`` into ``out`` with ``mem`` as its MEM; the fork's
    record. ``out`` must not exist; it appears whole or not at all."""
    from sc2data.rl.train import load_config, read_config

    cfg = load_config(run)
    if cfg.reward != "narration":
        raise Sc2DataError(f"{run} was trained with --reward {cfg.reward}; only a narration run "
                           f"has a MEM to replace")
    from sc2data.model.scorer import load_model

    load_model(mem)  # a one-line error unless it is a trained MEM
    if out.exists():
        raise Sc2DataError(f"{out} exists; a fork goes into a new folder")
    config = read_config(run)
    config["mem"] = str(mem)
    if "inputs" in config:  # what the reward reads, by content: the fork's MEM now
        from sc2data.rl.narration import load_narration
        from sc2data.rl.runs import input_digests

        # the other inputs (a starting policy's, a teacher's digest) stay as the run recorded them
        config["inputs"] = {**config["inputs"],
                            **input_digests(load_narration(cfg.narration), str(mem))}
    with new_folder(out, [run / name for name in COPIED]) as tmp:
        write_atomic(tmp / CONFIG, (json.dumps(config, indent=1, sort_keys=True) + "\n").encode())
        record = {"from_run": str(run), "from_mem": cfg.mem, "mem": str(mem),
                  "checkpoint_sha256": sha256_file(run / MODEL)}
        write_atomic(tmp / "fork.json", (json.dumps(record, indent=1) + "\n").encode())
    return record
