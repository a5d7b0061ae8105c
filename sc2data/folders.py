"""The folders sc2data writes — a dataset (with its labels), a pair set, a training run, an RL
run, a build — told apart by their files, described (``sc2data info``) and checked
(``sc2data verify``).

``verify`` checks everything a folder's readers rely on, by content:

* a dataset (``dataset.json``): every shard chunk through its checksum, every shard's sha256
  against the index, the dataset record, attributes and tables (:mod:`sc2data.data.audit`), and
  its labels if it has any (both files against ``labels.sha256``, and that they belong together);
* a pair set (``pairset.json``): its header, ``pairs.parquet`` and the packed splits against the
  recorded pair-set fingerprint, each split's schema and rows, and every packed chunk through its
  checksum;
* a training run (``state.json``): every run file against its recorded sha256, and the checkpoint
  loads (an unfinished run is reported as such, not as a fault);
* an RL run (``sc2data rl train --out``: ``config.json`` with an ``action_space``, ``model.zip``):
  its settings and progress records, the checkpoint archive through every member's CRC-32, the
  learning curve and evaluation reports (one not checkpointed yet is a note, not a fault);
* a build folder (``sc2data build --out``: ``rollout/`` and ``pairs/``): both, as above.

A folder that a live command is writing (it holds the folder's lock) is not checked: its files
change under the check, and a half-committed epoch is no damage. ``verify`` says which command
is writing it, in one line, and ``info`` marks what it shows as a moment of a write in progress.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.cli.cliopts import plural
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import writer
from sc2data.ground.formats import Shape, loads
from sc2data.ground.resume import CONFIG, EVAL, STATE, read_record, read_records
from sc2data.model.runs import METRICS
from sc2data.rl.runs import CURVE_CSV, MODEL, read_state

DATASET, PAIRSET, RUN, RL_RUN, BUILD = "dataset", "pair set", "training run", "RL run", "build"
"""What :func:`kind` answers."""


def _rl_run(folder: Path) -> bool:
    """An ``sc2data rl train`` run: a checkpoint or curve of its own, or a ``config.json`` naming
    an action space (what a MEM run's never does)."""
    if (folder / MODEL).is_file() or (folder / CURVE_CSV).is_file():
        return True
    try:
        record = loads((folder / CONFIG).read_bytes())
    except (OSError, ValueError):  # formats.loads: any depth, one ValueError
        return False
    return isinstance(record, dict) and "action_space" in record


def kind(folder: Path) -> str:
    """:data:`DATASET`, :data:`PAIRSET`, :data:`RUN`, :data:`RL_RUN` or :data:`BUILD`; a
    one-line error for anything else."""
    from sc2data.build import PAIRS_DIR, ROLLOUT_DIR

    if not folder.is_dir():
        why = "it is a file" if folder.exists() else "it does not exist"
        raise Sc2DataError(f"{folder} is not a folder sc2data writes ({why})")
    if (folder / "dataset.json").is_file():
        return DATASET
    if (folder / "pairset.json").is_file():
        return PAIRSET
    if _rl_run(folder):
        return RL_RUN
    if (folder / STATE).is_file() or (folder / CONFIG).is_file():
        return RUN
    if (folder / ROLLOUT_DIR / "dataset.json").is_file() or \
            (folder / PAIRS_DIR / "pairset.json").is_file():
        return BUILD
    raise Sc2DataError(f"{folder} holds no dataset.json, pairset.json, state.json or "
                       f"config.json: not a dataset (sc2data rollout), pair set (sc2data pair), "
                       f"training run (sc2data train), RL run (sc2data rl train) or build "
                       f"(sc2data build) folder")


def expect_dataset(folder: Path, flag: str = "DATA", *, builds: bool = False) -> Path:
    """``folder`` if it is a dataset folder, or could become one (absent, or none of sc2data's);
    a one-line error naming the dataset to pass instead when it is another folder sc2data
    writes (a pair set's source, a build's ``rollout/``; ``builds``: let a build folder pass,
    for a command that reads datasets inside it)."""
    from sc2data.build import ROLLOUT_DIR

    try:
        what = kind(folder)
    except Sc2DataError:
        return folder  # the command's own check says what is wrong
    if what == DATASET or (what == BUILD and builds):
        return folder
    if what == BUILD:
        raise Sc2DataError(f"{folder} is a build folder (sc2data build --out); its dataset is "
                           f"{folder / ROLLOUT_DIR}: pass that as {flag}")
    if what == PAIRSET:
        try:
            source = loads((folder / "pairset.json").read_text())["data"]["path"]
        except (OSError, ValueError, KeyError, TypeError):
            source = None
        where = f" ({source})" if isinstance(source, str) else ""
        raise Sc2DataError(f"{folder} is a pair set (sc2data pair), not a dataset; pass as {flag} "
                           f"the labelled dataset folder its pairs were drawn from{where}")
    made, article = ("sc2data rl train", "an") if what == RL_RUN else ("sc2data train", "a")
    raise Sc2DataError(f"{folder} is {article} {what} ({made} --out), not a dataset; pass as "
                       f"{flag} a dataset folder (sc2data rollout --out)")


def verify_folder(folder: Path) -> tuple[str, list[str], list[str]]:
    """(what the folder is, faults, notes); a one-line error for a folder being written now
    (before the check, or when one that found faults ends)."""
    _not_being_written(folder)
    what = kind(folder)
    if what == BUILD:
        faults, notes = _build(folder)
    else:
        faults, notes = _CHECKS[what](folder)
    if faults:  # a write that began during the check changed files under it
        _not_being_written(folder)
    return what, faults, notes


def writing(folder: Path) -> str | None:
    """The command writing ``folder`` now (``sc2data train (pid 12)``), or None: the holder of its
    lock, or of the one beside it (a pair set is written whole and renamed into place)."""
    return writer(folder) or writer(folder.parent, f".{folder.name}.lock")


def _not_being_written(folder: Path) -> None:
    holder = writing(folder)
    if holder is not None:
        raise Sc2DataError(f"{folder} is being written by {holder} now: a write in "
                           f"progress, its files not final yet; verify it when that command has "
                           f"finished")


def info(folder: Path) -> list[str]:
    """A plain-text description of the folder, whatever it is."""
    holder = writing(folder)
    what = kind(folder)
    note = [f"writing   {holder} is writing this folder now: what follows may change", ""] \
        if holder else []
    if what == DATASET:
        return note + _dataset_info(folder)
    if what == PAIRSET:
        return note + _pairset_info(folder)
    if what == RL_RUN:
        return note + _rl_info(folder)
    if what == BUILD:
        return note + _build_info(folder)
    return note + _run_info(folder)


def _dataset_info(folder: Path) -> list[str]:
    from sc2data.data.audit import info as dataset_info
    from sc2data.data.dataset import read_index
    from sc2data.labels.store import LABELS_FILE, read_meta

    lines = dataset_info(folder)
    marines = read_index(folder).column("reward").to_numpy()
    if len(marines):
        lines += ["", f"marines per episode (the game's score, from the index): mean "
                      f"{marines.mean():.1f}, min {marines.min():.0f}, max {marines.max():.0f} "
                      f"over {plural(len(marines), 'episode')}"]
    if not (folder / LABELS_FILE).exists():
        return lines + ["labels    none yet (sc2data label)"]
    try:
        meta = read_meta(folder)
    except Sc2DataError as e:
        return lines + [f"labels    not usable: {e}"]
    stacks = max(int(meta["stacks"]), 1)
    lines += ["", f"labels    {meta['stacks']:,} stacks, made {meta['created']}",
              f"{'rule id':<22} {'version':>7} {'stacks':>10} {'rate':>8}  command"]
    for r in meta["rules"]:
        n = int(meta["counts"].get(r["id"], 0))
        lines.append(f"{r['id']:<22} {r['version']:>7} {n:>10,} {100 * n / stacks:>7.3f}%  "
                     f"{r['command']}")
    lines.append(f"{'(null)':<22} {'':>7} {meta['null']:>10,} "
                 f"{100 * meta['null'] / stacks:>7.3f}%")
    return lines


def _pairset_info(folder: Path) -> list[str]:
    from sc2data.ground.vocab import SPLITS
    from sc2data.pairs.loader import PairSet

    p = PairSet(folder)
    meta = p.meta
    lines = [f"pair set  {folder}", f"recipe    {meta.get('recipe_name')}   seed {meta.get('seed')}"
             f"   split {meta.get('recipe', {}).get('split', {}).get('method', '?')}",
             "", f"{'split':<6} {'matched':>9} {'mismatched':>11} {'null':>8} {'states':>8}"]
    for s in SPLITS:
        c = meta.get("counts", {}).get(s, {})
        lines.append(f"{s:<6} {c.get('matched', 0):>9,} {c.get('mismatched', 0):>11,} "
                     f"{c.get('null', 0):>8,} {meta['splits'][s]['states']:>8,}")
    lines += ["", "commands"] + [f"  {c['id']:<20} {c['text']!r}" + (
        f"  held-out paraphrases: {', '.join(map(repr, c['paraphrases']))}"
        if c.get("paraphrases") else "") for c in p.commands]
    sources = meta.get("data", {}).get("sources") if isinstance(meta.get("data"), dict) else None
    if isinstance(sources, list):  # a recipe of several sources: the mix
        lines += ["", "sources (the pairs drawn from each)",
                  f"  {'name':<10} {'share':>6} {'train':>7} {'val':>7} {'test':>7}  agent, data"]
        for src in sources:
            per = src.get("states", {})
            n = [sum(per.get(s, {}).values()) for s in SPLITS]
            lines.append(f"  {src.get('name', '?'):<10} {100 * float(src.get('share', 0)):>5.1f}% "
                         + " ".join(f"{k:>7,}" for k in n)
                         + f"  {src.get('settings', {}).get('agent', '?')}, {src.get('path')}")
    return lines


METRICS_ROW: Shape = {k: int if k == "epoch" else float for k in
                      ("epoch", "train_loss", "train_acc", "val_loss", "val_acc")}
"""A row of a run's ``metrics.jsonl``, as ``info`` reads it."""
EVAL_SHAPE: Shape = {"splits?": {"*": {"accuracy?": (float, type(None))}}}
"""A run's ``eval.json``, as ``info`` reads it."""


def _records(path: Path, shape: Shape, lines: bool = False) -> list[Any]:
    """A run's JSON file (or its JSON lines), checked to have ``shape``; [] if it is absent."""
    if not path.is_file():
        return []
    return read_records(path, shape, "train the run again", lines=lines, finite=False)


def _run_info(folder: Path) -> list[str]:
    from sc2data.model.train import read_config, read_state

    config = read_config(folder) or {}
    state = read_state(folder)
    done = "no state.json" if state is None else (
        f"{state['epochs_done']} of {state['epochs']} epochs"
        + ("" if state["finished"] else " (unfinished: rerun the train command to resume)"))
    lines = [f"run       {folder}", f"data      {config.get('data')}", f"progress  {done}",
             "settings  " + "  ".join(f"{k}={config.get(k)}" for k in
                                      ("epochs", "batch_size", "lr", "l2", "seed",
                                       "categorical", "pool", "device_used"))]
    rows = _records(folder / METRICS, METRICS_ROW, lines=True)
    if rows:
        best = min(rows, key=lambda r: r["val_loss"])
        lines += ["", f"{'epoch':>5} {'train loss':>10} {'train acc':>9} {'val loss':>9} "
                      f"{'val acc':>8}"]
        lines += [f"{r['epoch']:>5} {r['train_loss']:>10.4f} {r['train_acc']:>9.2%} "
                  f"{r['val_loss']:>9.4f} {r['val_acc']:>8.2%}" + ("  *" if r is best else "")
                  for r in rows]
    for ev in _records(folder / EVAL, EVAL_SHAPE):
        acc = {s: v.get("accuracy") for s, v in ev.get("splits", {}).items()}
        lines += ["", "eval      " + "  ".join(f"{s} {a:.2%}" for s, a in acc.items()
                                               if isinstance(a, float))]
    return lines


def _faults_of(check: Callable[[], object]) -> list[str]:
    try:
        check()
    except Sc2DataError as e:
        return [str(e)]
    return []


def _dataset(folder: Path) -> tuple[list[str], list[str]]:
    from sc2data.data.audit import verify
    from sc2data.labels.store import LABELS_FILE, read_labels

    try:
        faults = verify(folder)
    except Sc2DataError as e:  # its record or index unreadable: nothing more can be checked
        return [str(e)], []
    if not (folder / LABELS_FILE).exists():
        return faults, ["no labels yet (sc2data label)"]
    return faults + _faults_of(lambda: read_labels(folder)), ["labels checked"]


def _pairset_faults(folder: Path) -> tuple[list[str], list[str]]:
    return _pairset(folder), []


def _pairset(folder: Path) -> list[str]:
    from sc2data.ground.vocab import SPLITS
    from sc2data.pairs.loader import PairSet

    try:
        pairs = PairSet(folder)
    except Sc2DataError as e:
        return [str(e)]
    faults = []
    for split in SPLITS:
        try:
            packed = pairs.packed(split)
            packed.check_chunks()
            packed.close()
        except Sc2DataError as e:
            faults.append(str(e))
    return faults


def _run(folder: Path) -> tuple[list[str], list[str]]:
    from sc2data.model.train import check_run, read_state

    try:
        state = read_state(folder)
        if state is None:
            return [f"{folder} has no state.json (written by an older sc2data, or interrupted "
                    f"before its first epoch)"], []
        check_run(folder, allow_unfinished=True, files=tuple(state["sha256"]))
        from sc2data.model.scorer import load_model

        load_model(folder, allow_unfinished=True)
    except Sc2DataError as e:
        return [str(e)], []
    notes = [] if state["finished"] else [f"unfinished: {state.get('epochs_done')} of "
                                          f"{state.get('epochs')} epochs"]
    return [], notes


# -- RL runs -----------------------------------------------------------------------------------
EVALS = (EVAL, "eval-stochastic.json")
"""An RL run's evaluation reports (``eval-stochastic.json`` from runs evaluated before both
modes went into ``eval.json``)."""
SCORES: Shape = {"mean": float, "std": float}
EVAL_REPORT: Shape = {"episodes": int, "sampled?": SCORES, "argmax?": SCORES, "mean?": float,
                      "std?": float, "deterministic?": bool}
"""What ``info`` reads of an RL evaluation report: sampled and argmax scores, or (older) one
mode's."""


def _rl_records(folder: Path) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """An RL run's settings (``config.json``) and progress (``state.json``, None before the
    first checkpoint), both checked."""
    from sc2data.rl.train import STATE_SHAPE, read_config

    config = read_config(folder)
    path = folder / STATE
    if not path.is_file():
        return config, None
    return config, read_record(path, STATE_SHAPE, f"delete {folder} and train it again, or "
                                                  f"pick another --out")


def _rl_evals(folder: Path) -> list[tuple[str, dict[str, Any]]]:
    out = []
    for name in EVALS:
        path = folder / name
        if path.is_file():
            out.append((name, read_record(path, EVAL_REPORT,
                                          f"rerun sc2data rl evaluate {folder}")))
    return out


def _rl_info(folder: Path) -> list[str]:
    from sc2data.rl.train import read_curve

    config, state = _rl_records(folder)
    done = "no checkpoint yet (rerun the same sc2data rl train command to resume)" \
        if state is None or not (folder / MODEL).is_file() else \
        (f"{plural(state['timesteps'], 'decision')}, {plural(state['env_steps'], 'pysc2 step')}, "
         f"{plural(state['episodes'], 'episode')}, resumed {plural(state['resumes'], 'time')}")
    narration = config.get("narration") or "the shipped BuildMarines narration"
    lines = [f"RL run    {folder}",
             f"reward    {config['reward']}" + (f" (MEM {config.get('mem')}, narration "
                                               f"{narration})" if config["reward"] == "narration"
                                               else ""),
             f"progress  {done}",
             "settings  " + "  ".join(f"{k}={config.get(k)}" for k in
                                      ("action_space", "obs", "envs", "seed", "bonus",
                                       "threshold", "rollout", "batch_size", "policy"))]
    try:
        rows = read_curve(folder)
    except (OSError, ValueError, KeyError) as e:
        raise Sc2DataError(f"{folder / CURVE_CSV} is unreadable ({e}); rerun the same "
                           f"sc2data rl train command to rewrite it") from None
    if rows:
        marines = np.array([r["marines"] for r in rows])
        tail = marines[-10:]
        lines += ["", f"curve     {plural(len(rows), 'training episode')}: marines per episode "
                      f"{marines.mean():.1f} mean, {tail.mean():.1f} over the last {len(tail)}"]
    for name, ev in _rl_evals(folder):
        modes = [(m, ev[m]) for m in ("sampled", "argmax") if m in ev] or \
            [("argmax" if ev.get("deterministic", True) else "sampled", ev)]
        for mode, score in modes:
            if "mean" in score:
                lines.append(f"eval      {mode}: {score['mean']:.2f} ± {score.get('std', 0):.2f} "
                             f"marines per episode over {plural(ev['episodes'], 'episode')} "
                             f"({name})")
    return lines


def _rl(folder: Path) -> tuple[list[str], list[str]]:
    import zipfile

    from sc2data.rl.train import read_curve

    try:
        config, state = _rl_records(folder)
    except Sc2DataError as e:
        return [str(e)], []
    faults: list[str] = []
    notes: list[str] = []
    model = folder / MODEL
    if state is None or not model.is_file():
        notes.append("no checkpoint yet")
    else:
        try:
            with zipfile.ZipFile(model) as archive:
                bad = archive.testzip()
            if bad is not None:
                faults.append(f"{model} is damaged: its member {bad} fails its CRC-32 check; "
                              f"delete {folder} and train it again")
        except (OSError, zipfile.BadZipFile, EOFError) as e:
            faults.append(f"{model} is not a readable checkpoint ({type(e).__name__}: {e}); "
                          f"delete {folder} and train it again")

    try:  # the model and curve against the sha256 the last checkpoint recorded
        read_state(folder)
    except Sc2DataError as e:
        faults.append(str(e))
        return faults, notes
    try:
        rows = read_curve(folder)
        if state is not None and rows and max(r["timesteps"] for r in rows) > state["timesteps"] \
                + config["envs"] * config["rollout"]:
            faults.append(f"{folder / CURVE_CSV} runs past the {state['timesteps']} decisions "
                          f"state.json records; rerun the same sc2data rl train command")
    except (OSError, ValueError, KeyError) as e:
        faults.append(f"{folder / CURVE_CSV} is unreadable ({e}); rerun the same sc2data rl "
                      f"train command to rewrite it")
    faults += _faults_of(lambda: _rl_evals(folder))
    return faults, notes


# -- build folders -----------------------------------------------------------------------------
def _build_parts(folder: Path) -> list[tuple[str, Path]]:
    from sc2data.build import PAIRS_DIR, ROLLOUT_DIR

    return [(what, folder / sub) for what, sub in ((DATASET, ROLLOUT_DIR), (PAIRSET, PAIRS_DIR))]


def _build_info(folder: Path) -> list[str]:
    lines = [f"build     {folder} (sc2data build): its dataset and its pair set", ""]
    for what, part in _build_parts(folder):
        if kind_of(part) != what:
            lines += [f"{part.name:<9} not made yet (rerun the sc2data build command to "
                      f"resume)", ""]
            continue
        try:
            lines += (_dataset_info(part) if what == DATASET else _pairset_info(part)) + [""]
        except Sc2DataError as e:
            lines += [f"{part.name:<9} not usable: {e}", ""]
    return lines[:-1]


def _build(folder: Path) -> tuple[list[str], list[str]]:
    faults: list[str] = []
    notes: list[str] = []
    for what, part in _build_parts(folder):
        if kind_of(part) != what:
            notes.append(f"{part.name}/ not made yet")
            continue
        _not_being_written(part)
        f, n = _CHECKS[what](part)
        faults += f
        notes += [f"{part.name}/: {x}" for x in n] or [f"{part.name}/ checked"]
    return faults, notes


def kind_of(folder: Path) -> str | None:
    """:func:`kind`, or None for a folder that is none of sc2data's."""
    try:
        return kind(folder)
    except Sc2DataError:
        return None


_CHECKS: dict[str, Callable[[Path], tuple[list[str], list[str]]]] = {
    DATASET: lambda f: _dataset(f), PAIRSET: _pairset_faults, RUN: lambda f: _run(f),
    RL_RUN: lambda f: _rl(f)}
"""``verify`` of each kind but a build (faults, notes)."""
