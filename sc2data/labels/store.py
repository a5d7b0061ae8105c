"""The label files in a dataset folder: writing them whole, and reading them back checked.

* ``labels.parquet`` — one row per (stack, rule) that fired: ``episode``, ``step``, ``rule_id``
  (the command's id), ``rule_version``, ``command`` (its canonical text).
* ``stack_labels.parquet`` — one row per labelled stack: ``episode``, ``step`` and one bool column
  per rule id. It is how the pair stage finds *null* stacks (no column true) and checks that a
  mismatched state does not in fact satisfy a command; ``labels.parquet`` is its long form.

Both carry the same JSON under the Parquet metadata key ``sc2data.labels``: the rules' ids,
versions, texts, sources and code hashes, the dataset they came from, the counts and a
fingerprint; :func:`read_labels` refuses a pair of files whose fingerprints differ.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from sc2data.errors import Sc2DataError
from sc2data.files import atomic_file

LABELS_FILE = "labels.parquet"
STACKS_FILE = "stack_labels.parquet"
META_KEY = b"sc2data.labels"
FORMAT_VERSION = 1


def write_table(table: pa.Table, path: Path, meta: dict[str, Any] | None = None) -> None:
    """Write a Parquet table atomically, with the labels' provenance record if given."""
    if meta is not None:
        table = table.replace_schema_metadata({META_KEY: json.dumps(meta).encode()})
    with atomic_file(path) as tmp:
        pq.write_table(table, tmp)


def read_meta(folder: Path | str) -> dict[str, Any]:
    """The provenance record of the labels in ``folder``."""
    path = Path(folder) / LABELS_FILE
    if not path.is_file():
        raise Sc2DataError(f"no labels in {folder}; run sc2data label {folder} first")
    raw = (pq.read_schema(path).metadata or {}).get(META_KEY)
    if raw is None:
        raise Sc2DataError(f"{path} was not written by sc2data label; relabel with sc2data label")
    return json.loads(raw)


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
    stacks = pq.read_table(stacks_path)
    other = json.loads((stacks.schema.metadata or {}).get(META_KEY, b"{}"))
    if other.get("fingerprint") != meta["fingerprint"] or other.get("created") != meta["created"]:
        raise Sc2DataError(f"{LABELS_FILE} and {STACKS_FILE} in {folder} come from different "
                           f"runs; rerun sc2data label {folder}")
    return Labels(pq.read_table(Path(folder) / LABELS_FILE), stacks, meta)
