"""The folders sc2data writes — a dataset (with its labels), a pair set, a training run — told
apart by their files, described (``sc2data info``) and checked (``sc2data verify``).

``verify`` checks everything a folder's readers rely on, by content:

* a dataset (``dataset.json``): every shard chunk through its checksum, every shard's sha256
  against the index, manifest, attributes and tables (:mod:`sc2data.data.audit`), and its labels
  if it has any (both files against ``labels.sha256``, and that they belong together);
* a pair set (``pairset.json``): its header, ``pairs.parquet`` and the packed splits against the
  recorded fingerprint, each split's schema and rows, and every packed chunk through its checksum;
* a training run (``state.json``): every run file against its recorded sha256, and the checkpoint
  loads (an unfinished run is reported as such, not as a fault).

A folder that a live command is writing (it holds the folder's lock) is not checked: its files
change under the check, and a half-committed epoch is no damage. ``verify`` says which command
is writing it, in one line, and ``info`` marks what it shows as a moment of a write in progress.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from sc2data.errors import Sc2DataError
from sc2data.files import writer
from sc2data.formats import Shape, check_record, loads


def kind(folder: Path) -> str:
    """``dataset``, ``pair set`` or ``training run``; a one-line error for anything else."""
    if not folder.is_dir():
        why = "it is a file" if folder.exists() else "it does not exist"
        raise Sc2DataError(f"{folder} is not a folder sc2data writes ({why})")
    if (folder / "dataset.json").is_file():
        return "dataset"
    if (folder / "pairset.json").is_file():
        return "pair set"
    if (folder / "state.json").is_file() or (folder / "config.json").is_file():
        return "training run"
    raise Sc2DataError(f"{folder} holds no dataset.json, pairset.json or state.json: not a "
                       f"dataset (sc2data rollout), pair set (sc2data pair) or training run "
                       f"(sc2data train) folder")


def verify_folder(folder: Path) -> tuple[str, list[str], list[str]]:
    """(what the folder is, faults, notes); a one-line error for a folder being written now
    (before the check, or when one that found faults ends)."""
    _not_being_written(folder)
    what = kind(folder)
    if what == "dataset":
        faults, notes = _dataset(folder)
    elif what == "pair set":
        faults, notes = _pairset(folder), []
    else:
        faults, notes = _run(folder)
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
    if what == "dataset":
        return note + _dataset_info(folder)
    if what == "pair set":
        return note + _pairset_info(folder)
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
                      f"over {len(marines)} episodes"]
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
    from sc2data.pairs.loader import PairSet
    from sc2data.vocab import SPLITS

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
    try:
        text = path.read_text()
        records = [loads(t, finite=False) for t in text.splitlines()] if lines else \
            [loads(text, finite=False)]
    except (OSError, ValueError) as e:
        raise Sc2DataError(f"{path} is unreadable ({e}); train the run again") from None
    for r in records:
        check_record(r, shape, path, "train the run again")
    return records


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
    rows = _records(folder / "metrics.jsonl", METRICS_ROW, lines=True)
    if rows:
        best = min(rows, key=lambda r: r["val_loss"])
        lines += ["", f"{'epoch':>5} {'train loss':>10} {'train acc':>9} {'val loss':>9} "
                      f"{'val acc':>8}"]
        lines += [f"{r['epoch']:>5} {r['train_loss']:>10.4f} {r['train_acc']:>9.2%} "
                  f"{r['val_loss']:>9.4f} {r['val_acc']:>8.2%}" + ("  *" if r is best else "")
                  for r in rows]
    for ev in _records(folder / "eval.json", EVAL_SHAPE):
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


def _pairset(folder: Path) -> list[str]:
    from sc2data.pairs.loader import PairSet
    from sc2data.vocab import SPLITS

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
        from sc2data.model.reward import load_model

        load_model(folder, allow_unfinished=True)
    except Sc2DataError as e:
        return [str(e)], []
    notes = [] if state["finished"] else [f"unfinished: {state.get('epochs_done')} of "
                                          f"{state.get('epochs')} epochs"]
    return [], notes
