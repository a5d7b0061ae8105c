"""``sc2data verify FOLDER``: is any folder sc2data writes intact? It finds what the folder is by
its files and checks everything its readers rely on, by content:

* a dataset (``dataset.json``): every shard chunk through its checksum, every shard's sha256
  against the index, manifest, attributes and tables (:mod:`sc2data.data.audit`), and its labels
  if it has any (both files against ``labels.sha256``, and that they belong together);
* a pair set (``pairset.json``): its header, ``pairs.parquet`` and the packed splits against the
  recorded fingerprint, each split's schema and rows, and every packed chunk through its checksum;
* a training run (``state.json``): every run file against its recorded sha256, and the checkpoint
  loads (an unfinished run is reported as such, not as a fault).
"""

from __future__ import annotations

from pathlib import Path

from sc2data.errors import Sc2DataError


def verify_folder(folder: Path) -> tuple[str, list[str], list[str]]:
    """(what the folder is, faults, notes); an unrecognisable folder is a one-line error."""
    if not folder.is_dir():
        why = "it is a file" if folder.exists() else "it does not exist"
        raise Sc2DataError(f"{folder} is not a folder sc2data writes ({why})")
    if (folder / "dataset.json").is_file():
        return ("dataset", *_dataset(folder))
    if (folder / "pairset.json").is_file():
        return "pair set", _pairset(folder), []
    if (folder / "state.json").is_file() or (folder / "best.pt").is_file():
        return ("training run", *_run(folder))
    raise Sc2DataError(f"{folder} holds no dataset.json, pairset.json or state.json: not a "
                       f"dataset, pair set or training run folder")


def _faults_of(check: object) -> list[str]:
    try:
        check()  # type: ignore[operator]
    except Sc2DataError as e:
        return [str(e)]
    return []


def _dataset(folder: Path) -> tuple[list[str], list[str]]:
    from sc2data.data.audit import verify
    from sc2data.labels.store import LABELS_FILE, read_labels

    faults = verify(folder)
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
