"""The label files in a dataset folder: writing them whole, and reading them back checked.

* ``labels.parquet`` — one row per (stack, rule) that fired: ``episode``, ``step``, ``rule_id``
  (the command's id), ``rule_version``, ``command`` (its canonical text).
* ``stack_labels.parquet`` — one row per labelled stack: ``episode``, ``step`` and one bool column
  per rule id. It is how the pair stage finds *null* stacks (no column true) and checks that a
  mismatched state does not in fact satisfy a command; ``labels.parquet`` is its long form.

``labels.sha256`` records both files' sha256 (written last): every read checks them, so a damaged
label file is an error wherever it is read, never a different pair set.

Both carry the same JSON under the Parquet metadata key ``sc2data.labels``: the rules' ids,
versions, texts, sources and code hashes, the dataset they came from, the counts and the labels
fingerprint; :func:`read_labels` refuses a pair of files whose fingerprints differ.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import atomic_file, sha256_file, write_atomic
from sc2data.ground.formats import loads

LABELS_FILE = "labels.parquet"
STACKS_FILE = "stack_labels.parquet"
META_KEY = b"sc2data.labels"
FORMAT_VERSION = 1
SUMS_FILE = "labels.sha256"
"""JSON ``{file name: sha256}`` of the two label files."""


def write_table(table: pa.Table, path: Path, meta: dict[str, Any] | None = None) -> None:
    """Write a Parquet table atomically, with the labels' provenance record if given."""
    if meta is not None:
        table = table.replace_schema_metadata({META_KEY: json.dumps(meta).encode()})
    with atomic_file(path) as tmp:
        pq.write_table(table, tmp)


def write_sums(path: Path, files: list[Path]) -> None:
    """Record ``files``' sha256 in the JSON file ``path`` (atomically)."""
    sums = {f.name: sha256_file(f) for f in files}
    write_atomic(path, (json.dumps(sums, indent=1, sort_keys=True) + "\n").encode())


def check_sums(path: Path, rerun: str) -> None:
    """One-line error unless every file listed in ``path`` has the sha256 recorded there."""
    try:
        sums = loads(path.read_text())
        if not isinstance(sums, dict) or not sums:
            raise ValueError("not a table of files")
    except FileNotFoundError:
        raise Sc2DataError(f"{path} is missing (an interrupted or older run); {rerun}") from None
    except (OSError, ValueError) as e:
        raise Sc2DataError(f"{path} is unreadable ({e}); {rerun}") from None
    for name, digest in sums.items():
        f = path.parent / str(name)
        if not f.is_file() or sha256_file(f) != digest:
            raise Sc2DataError(f"{f} is damaged or was replaced (its sha256 differs from "
                               f"{path.name}); {rerun}")


def write_labels(folder: Path, wide: pa.Table, fired: pa.Table, meta: dict[str, Any]) -> None:
    """Both label files, then their checksums."""
    write_table(wide, folder / STACKS_FILE, meta)
    write_table(fired, folder / LABELS_FILE, meta)
    write_sums(folder / SUMS_FILE, [folder / STACKS_FILE, folder / LABELS_FILE])


def check_labels(folder: Path | str) -> None:
    """One-line error unless both label files are present and intact."""
    folder = Path(folder)
    if not (folder / LABELS_FILE).is_file():
        raise Sc2DataError(f"no labels in {folder}; run sc2data label {folder} first")
    check_sums(folder / SUMS_FILE, f"rerun sc2data label {folder}")


def file_meta(path: Path) -> dict[str, Any]:
    """The provenance record in one label file's Parquet metadata."""
    try:
        raw = (pq.read_schema(path).metadata or {}).get(META_KEY)
        if raw is None:
            raise Sc2DataError(f"{path} was not written by sc2data label; relabel with sc2data "
                               f"label")
        meta = loads(raw)
    except (OSError, ValueError, pa.ArrowException) as e:
        raise Sc2DataError(f"{path} is unreadable ({type(e).__name__}); rerun sc2data label "
                           f"{path.parent}") from None
    if not isinstance(meta, dict) or not {"fingerprint", "created", "rules"} <= set(meta):
        raise Sc2DataError(f"{path} has no valid sc2data labels record; rerun sc2data label "
                           f"{path.parent}")
    return meta


def read_meta(folder: Path | str) -> dict[str, Any]:
    """The provenance record of the labels in ``folder``, after checking both files are intact."""
    check_labels(folder)
    return file_meta(Path(folder) / LABELS_FILE)


@dataclass(frozen=True)
class Labels:
    """A folder's labels: the long table, the per-stack table, and their provenance record."""

    fired: pa.Table
    stacks: pa.Table
    meta: dict[str, Any]

    def __repr__(self) -> str:
        return (f"Labels(fired={self.fired.num_rows}, stacks={self.stacks.num_rows}, "
                f"rules={[r['id'] for r in self.meta['rules']]})")


def read_labels(folder: Path | str) -> Labels:
    """Both label tables of ``folder``, checked to come from the same run."""
    meta = read_meta(folder)
    stacks_path = Path(folder) / STACKS_FILE
    if not stacks_path.is_file():
        raise Sc2DataError(f"{stacks_path} is missing; rerun sc2data label {folder}")
    other = file_meta(stacks_path)
    if other.get("fingerprint") != meta["fingerprint"] or other.get("created") != meta["created"]:
        raise Sc2DataError(f"{LABELS_FILE} and {STACKS_FILE} in {folder} come from different "
                           f"runs; rerun sc2data label {folder}")
    try:
        return Labels(pq.read_table(Path(folder) / LABELS_FILE), pq.read_table(stacks_path), meta)
    except (OSError, pa.ArrowException) as e:
        raise Sc2DataError(f"the labels in {folder} are unreadable ({type(e).__name__}); rerun "
                           f"sc2data label {folder}") from None
