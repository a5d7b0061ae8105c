"""An RL run folder: its files named once, its records checked, and a checkpoint that is whole.

``sc2data rl train --out RUN`` writes:

* ``config.json`` — the settings (:class:`~sc2data.rl.train.RLConfig`) and, under ``inputs``,
  the sha256 of what the reward reads: the narration's commands and the MEM's checkpoint. A
  resume with other settings, an edited narration or another MEM at the same path is refused.
* ``model.zip`` (sb3-contrib's format), ``curve.csv`` / ``curve.json`` (one row per finished
  training episode) and ``state.json`` (decisions, pysc2 steps, episodes, resumes, and the
  sha256 of the model and of the curve) — one checkpoint, committed as a whole:
  the model and curve are written as ``*.partial`` files, then ``state.partial.json`` naming
  their sha256, then each is renamed into place, ``state.json`` last. A stop anywhere leaves either
  the previous checkpoint or the new one (:func:`recover` finishes or discards a commit it finds
  half done), so a resume never pairs a model with another checkpoint's count or curve.
* ``logs/<resume>/progress.csv`` (and TensorBoard events with ``--tensorboard``): SB3's logger,
  PPO's own figures per update (losses, entropy, approximate KL, clip fraction, explained
  variance) beside the game's score, one folder per training session.

A *record* (``sc2data rl record``, :mod:`sc2data.rl.record`) is a finished run without its
model: ``config.json``, ``curve.csv``, ``eval.json`` and ``record.json`` (the
model's sha256 and those of the curve and evaluation). ``rl compare`` and ``rl plot`` read it as
a run; whatever needs the model refuses it in one line (:func:`is_record`).

Every file is checked by content where it is read: a model, curve or state that is not the one
the last checkpoint recorded is a one-line error, never trained on, evaluated or plotted.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
import shutil
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from sc2data.ground import resume
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import PARTIAL, check_out, publish, sha256_file, write_atomic, writing
from sc2data.ground.formats import Shape, loads
from sc2data.ground.resume import CONFIG, EVAL, STATE
from sc2data.model.runs import BEST

__all__ = ["CONFIG", "EVAL", "STATE", "sha256_file"]

MODEL = "model.zip"
CURVE_CSV = "curve.csv"
CURVE_JSON = "curve.json"
LOGS = "logs"
MODEL_PARTIAL = "model.partial.zip"
CURVE_PARTIAL = "curve.partial.csv"
STATE_PARTIAL = "state.partial.json"
RECORD = "record.json"

CURVE_FIELDS: tuple[str, ...] = ("episode", "env", "timesteps", "env_steps", "marines",
                                 "game_return", "return")
STATE_SHAPE: Shape = {"timesteps": int, "env_steps": int, "episodes": int, "resumes": int,
                      "model_sha256?": str, "curve_sha256?": str}
"""``state.json``: what has been trained so far, and the checkpoint's files by content (runs
written before the sha256 were recorded lack them and are read without that check)."""


RECORD_SHAPE: Shape = {"from_run": str, "timesteps": int, "env_steps": int, "episodes": int,
                       "model_sha256?": str, "curve_sha256": str, "eval_sha256": str,
                       "recorded_by": str}
"""``record.json``; ``model_sha256`` is absent only where the run's checkpoint did not record it."""


def remedy(run: Path) -> str:
    if is_record(run):
        return f"record {run} again from its run (sc2data rl record RUN --out {run})"
    return f"delete {run} and train it again, or pick another --out"


def is_record(run: Path) -> bool:
    """Whether ``run`` is a run's record (no model: compared and plotted, never played)."""
    return (run / RECORD).is_file()


def no_model(run: Path) -> str:
    """The one line for a command that needs a record's model."""
    return (f"{run} is a run's record (sc2data rl record): it has no model to play, evaluate or "
            f"train; use the run it was recorded from ({RECORD}: from_run)")


def read_record(path: Path, shape: Shape, run: Path) -> dict[str, Any]:
    """A run record, parsed (any depth, one line) and checked to have ``shape``."""
    return resume.read_record(path, shape, remedy(run))  # type: ignore[no-any-return]


def write_record(path: Path, data: Any) -> None:
    write_atomic(path, (json.dumps(data, indent=1, sort_keys=True) + "\n").encode())


def curve_bytes(rows: Sequence[dict[str, float]]) -> bytes:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CURVE_FIELDS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (int(r[k]) if float(r[k]).is_integer() else r[k]) for k in CURVE_FIELDS})
    return buf.getvalue().encode()


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def recover(run: Path) -> None:
    """Finish a checkpoint whose commit a stop interrupted, or discard it: afterwards the run
    holds one whole checkpoint (or none) and no partial file."""
    partial = run / STATE_PARTIAL
    if partial.is_file():
        try:
            record = loads(partial.read_bytes())
            want = {MODEL: record["model_sha256"], CURVE_CSV: record["curve_sha256"]}
        except (OSError, ValueError, KeyError, TypeError):
            want = {}
        moves = {MODEL: MODEL_PARTIAL, CURVE_CSV: CURVE_PARTIAL}
        whole = bool(want)
        for final, sha in want.items():
            staged = run / moves[final]
            if staged.is_file() and sha256_file(staged) == sha:
                staged.replace(run / final)
            whole = whole and (run / final).is_file() and sha256_file(run / final) == sha
        if whole:
            partial.replace(run / STATE)
    for name in (STATE_PARTIAL, MODEL_PARTIAL, CURVE_PARTIAL):
        (run / name).unlink(missing_ok=True)


def read_state(run: Path) -> dict[str, Any] | None:
    """The last checkpoint's record (None before the first), its model and curve checked; a
    record's (:func:`is_record`) checked by its ``record.json``."""
    if is_record(run):
        return read_record_state(run)
    if not (run / STATE).is_file():
        if (run / MODEL).is_file():
            raise Sc2DataError(f"{run} holds {MODEL} but no {STATE} (what it was trained "
                               f"for); {remedy(run)}")
        return None
    state = read_record(run / STATE, STATE_SHAPE, run)
    check_model(run, state)
    if "curve_sha256" in state:
        path = run / CURVE_CSV
        if not path.is_file() or sha256_file(path) != state["curve_sha256"]:
            raise Sc2DataError(f"{path} is not the curve {STATE} records (changed or damaged "
                               f"since training wrote it); {remedy(run)}")
    return state


def read_record_state(run: Path) -> dict[str, Any]:
    """A record's ``record.json``, its curve and evaluation checked by content (what
    :func:`read_state` gives for a run)."""
    entry: dict[str, Any] = read_record(run / RECORD, RECORD_SHAPE, run)
    for name, key in ((CURVE_CSV, "curve_sha256"), (EVAL, "eval_sha256")):
        path = run / name
        if not path.is_file() or sha256_file(path) != entry[key]:
            raise Sc2DataError(f"{path} is not the one {RECORD} records (changed or damaged "
                               f"since it was recorded); {remedy(run)}")
    return entry


def check_model(run: Path, state: dict[str, Any]) -> None:
    """One line unless ``model.zip`` is the model ``state`` records."""
    path = run / MODEL
    if not path.is_file():
        raise Sc2DataError(f"{run} has no {MODEL}; {remedy(run)}")
    if "model_sha256" in state and sha256_file(path) != state["model_sha256"]:
        raise Sc2DataError(f"{path} is not the model {STATE} records (another run's, or "
                           f"damaged); {remedy(run)}")


def load_model(run: Path, env: Any, device: str = "cpu", attach: bool = False) -> Any:
    """``RUN/model.zip`` as a MaskablePPO agent (:class:`~sc2data.rl.pipeline.PipelinedPPO`;
    checked by content first: :func:`read_state`); one line unless it observes and acts in
    ``env``'s spaces (a model of another action space or observation). ``attach``: the agent
    trains on ``env`` (a vector env)."""
    import zipfile

    from sc2data.rl.pipeline import PipelinedPPO

    if is_record(run):
        raise Sc2DataError(no_model(run))
    path = run / MODEL
    try:
        model = PipelinedPPO.load(path, env=env if attach else None, device=device)
    except (ValueError, KeyError, EOFError, RuntimeError, zipfile.BadZipFile) as e:
        if "spaces do not match" in str(e):  # SB3's check against the env
            raise Sc2DataError(f"{path} was trained for other observations or actions than "
                               f"{CONFIG}'s settings; {remedy(run)}") from None
        first = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise Sc2DataError(f"cannot load {path}: {first}; {remedy(run)}") from None
    for what in ("observation", "action"):
        if not attach and getattr(model, f"{what}_space") != getattr(env, f"{what}_space"):
            raise Sc2DataError(f"{path} was trained for other {what}s than {CONFIG}'s "
                               f"settings ({getattr(model, f'{what}_space')} against "
                               f"{getattr(env, f'{what}_space')}); {remedy(run)}")
    return model


def commit(run: Path, model: Any, rows: Sequence[dict[str, float]], curve_json: Any,
           state: dict[str, Any]) -> None:
    """Write a checkpoint as a whole (see the module docstring); ``state`` gains the sha256.
    A failure part-way (a full disk, Ctrl-C) leaves the previous checkpoint, or this one if its
    record was written, and no partial file."""
    try:
        model.save(run / MODEL_PARTIAL)
        curve = curve_bytes(rows)
        write_atomic(run / CURVE_PARTIAL, curve)
        state.update(model_sha256=sha256_file(run / MODEL_PARTIAL), curve_sha256=_sha(curve))
        write_record(run / STATE_PARTIAL, state)
    finally:
        recover(run)
    # derived from the committed rows, for readers; a stop before it leaves the last one's
    write_record(run / CURVE_JSON, curve_json)


def read_curve(run: Path) -> list[dict[str, float]]:
    """The learning curve rows of a run (an empty list before the first episode ends); one
    line if ``curve.csv`` is not what the last checkpoint recorded or cannot be read."""
    path = run / CURVE_CSV
    if not path.is_file():
        return []
    read_state(run)  # the curve is checked against the checkpoint that recorded it
    try:
        with path.open(newline="") as f:
            rows = [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]
    except (OSError, ValueError, TypeError, csv.Error) as e:
        raise Sc2DataError(f"cannot read {path}: {e}; {remedy(run)}") from None
    if rows and set(rows[0]) != set(CURVE_FIELDS):
        raise Sc2DataError(f"{path} does not hold the fields {', '.join(CURVE_FIELDS)}; "
                           f"{remedy(run)}")
    return rows


def check_file_out(path: Path) -> None:
    """One line, before any work, unless ``path`` can be written as a file: no folder there,
    no file above it."""
    check_out(path)
    if path.is_dir():
        raise Sc2DataError(f"cannot write {path}: it is a folder; --out takes a file name")


@contextlib.contextmanager
def new_folder(out: Path, copied: Sequence[Path], replace: bool = False) -> Iterator[Path]:
    """A folder that appears whole or not at all (``rl fork``, ``rl record``): ``copied``
    files (those that exist) copied into a hidden staging folder that the block fills further,
    which then takes ``out``'s name — replacing ``out`` with ``replace``. On any failure the
    staging folder is removed and ``out`` is as it was; a full disk is one line."""
    tmp = out.with_name(f".{out.name}{PARTIAL}")
    old = out.with_name(f".{out.name}.old")
    for stale in (tmp, old):
        shutil.rmtree(stale, ignore_errors=True)
    with writing(str(out), "free some space, then rerun the same command"):
        tmp.mkdir(parents=True)
        try:
            for path in copied:
                if path.is_file():
                    shutil.copy2(path, tmp / path.name)
            yield tmp
            if replace and out.exists():
                out.replace(old)
            publish(tmp, out)
        except BaseException:
            if old.exists() and not out.exists():
                old.replace(out)
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        shutil.rmtree(old, ignore_errors=True)


def write_file(path: Path, data: bytes) -> None:
    """``path`` written atomically, its parents made; a full disk is one line."""
    with writing(str(path), "free some space, then rerun the same command"):
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, data)


def input_digests(narration: Any, mem: str | None) -> dict[str, str]:
    """What the reward reads, by content: the narration's commands, the MEM's checkpoint."""
    out: dict[str, str] = {}
    if narration is not None:
        out["narration_sha256"] = _sha("\n".join(narration.commands).encode())
    if mem is not None:
        path = Path(mem)
        ckpt = path / BEST if path.is_dir() else path
        out["mem_sha256"] = sha256_file(ckpt)
    return out
