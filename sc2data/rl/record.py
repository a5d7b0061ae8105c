"""``sc2data rl record``: a finished run kept without its model, for comparing and plotting.

A paper-space run's ``model.zip`` is 3.4 MB; what ``rl compare`` and ``rl plot`` read of a run —
its settings, its training curve and its evaluation — is about 20 kB. An experiment that
outlives the machine it ran on (ten seeds of 1,000,000 decisions over several sittings) keeps
each finished run's record beside its figures and compares records and runs alike
(``benchmarks/rl_experiment.py --records``).

A record folder holds the run's ``config.json`` (settings and the digests of what its reward
read), ``curve.csv`` and ``eval.json``, and ``record.json``: the run it came
from, its trained decisions, the sha256 of its model (which checkpoint was evaluated) and of
the curve and evaluation copied, each checked where a record is read. The folder appears whole
or not at all; recording again into a record replaces it. What needs the model (``rl train``,
``evaluate``, ``agreement``, ``fork``, a policy rollout) refuses a record in one line.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import FolderLock, check_out, sha256_file, write_atomic
from sc2data.ground.provenance import versions
from sc2data.rl.runs import CONFIG, CURVE_CSV, EVAL, RECORD, is_record, new_folder

COPIED = (CONFIG, CURVE_CSV, EVAL)
"""What a record keeps of its run (not ``curve.json``: derived from ``curve.csv``, four times its
size)."""


def record(run: Path, out: Path) -> dict[str, Any]:
    """Write the record of the trained, evaluated run ``run`` into ``out`` (a new folder, or a
    record to replace); returns ``record.json``'s content."""
    from sc2data.rl.evaluate import read_eval
    from sc2data.rl.runs import read_state
    from sc2data.rl.train import load_config

    if is_record(run):
        raise Sc2DataError(f"{run} is a record already; copy the folder to keep another")
    if not (run / CONFIG).is_file():
        load_config(run)  # the one line for a folder that is not a trained run
    with FolderLock(run, "rl record"):  # not trained on while it is copied
        load_config(run)  # a trained run, its model and curve checked by content
        read_eval(run)  # evaluated at the decisions it has trained
        state = read_state(run) or {}
        check_out(out)
        if out.exists() and not is_record(out):
            raise Sc2DataError(f"{out} exists and is not a run's record; pick another --out")
        entry: dict[str, Any] = {
            "from_run": str(run.resolve()), "timesteps": int(state.get("timesteps", 0)),
            "env_steps": int(state.get("env_steps", 0)),
            "episodes": int(state.get("episodes", 0)),
            "recorded_by": f"sc2data {versions()['sc2data']}"}
        if "model_sha256" in state:
            entry["model_sha256"] = state["model_sha256"]
        with new_folder(out, [run / name for name in COPIED], replace=True) as tmp:
            # the digests of what was copied, which must be the checkpoint's: a run evaluated
            # again while it was copied (rl evaluate takes no lock) is refused, not recorded
            # half old, half new
            entry.update(curve_sha256=sha256_file(tmp / CURVE_CSV),
                         eval_sha256=sha256_file(tmp / EVAL))
            if entry["curve_sha256"] != state.get("curve_sha256", entry["curve_sha256"]) or \
                    read_eval_at(tmp) != entry["timesteps"]:
                raise Sc2DataError(f"{run} changed while it was recorded (trained or evaluated "
                                   f"again); rerun the same command")
            # the record file last: a folder without it is not a record
            write_atomic(tmp / RECORD,
                         (json.dumps(entry, indent=1, sort_keys=True) + "\n").encode())
    return entry


def read_eval_at(folder: Path) -> Any:
    """The decisions ``folder``'s evaluation was made at."""
    try:
        return json.loads((folder / EVAL).read_text()).get("trained_timesteps")
    except (OSError, ValueError, AttributeError):
        return None
