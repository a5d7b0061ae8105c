"""The pure core of labelling: run rules over batches of stacks, checking what they need and
what they answer. No folders and no resuming here (that is :mod:`sc2data.labels.label`);
:func:`write_part` labels one unit into one Parquet part, the way every process contributes."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.formats import loads
from sc2data.labels.registry import Registered, call, check_output
from sc2data.labels.source import Batches, WorkUnit
from sc2data.labels.store import FORMAT_VERSION, write_sums, write_table
from sc2data.schema import Schema


def check_requirements(rules: Sequence[Registered], schema: Schema, where: str) -> None:
    """One-line error for the first rule needing a key the data does not store."""
    stored = set(schema.keys())
    for e in rules:
        missing = [k for k in e.rule.requires if k not in stored]
        if missing:
            raise Sc2DataError(
                f"rule {e.id!r} ({e.source}) needs {', '.join(map(repr, missing))}, which {where} "
                f"does not store; roll out with a layer set that keeps it, or leave the rule out "
                f"with --exclude {e.id}")


def required_keys(rules: Sequence[Registered], schema: Schema) -> tuple[str, ...]:
    """The union of the rules' requirements, in schema order."""
    wanted = {k for e in rules for k in e.rule.requires}
    return tuple(k for k in schema.keys() if k in wanted)


def label_batches(batches: Batches, rules: Sequence[Registered],
                  on_batch: Callable[[int], None] | None = None) -> pa.Table:
    """Run the rules over ``batches``: a table of ``episode``, ``step``, one bool column per rule.

    Every answer is checked (shape, dtype) and any exception becomes a one-line error naming the
    rule and the stacks it failed on.
    """
    episodes: list[np.ndarray] = []
    steps: list[np.ndarray] = []
    fired: list[list[np.ndarray]] = [[] for _ in rules]
    for ep, st, batch in batches:
        n = len(batch)
        if n == 0:
            continue
        ep, st = np.asarray(ep), np.asarray(st)
        where = f"the stacks from episode {ep[0]} step {st[0]} to episode {ep[-1]} step {st[-1]}"
        for col, e in zip(fired, rules):
            col.append(check_output(e.rule, e.source, call(e.rule, e.source, batch, where), n,
                                    where))
        episodes.append(ep)
        steps.append(st)
        if on_batch is not None:
            on_batch(n)
    episode = np.concatenate(episodes) if episodes else np.zeros(0, np.int64)
    cols: dict[str, Any] = {  # the pair stage's types: int64 episode ids, int32 steps
        "episode": episode.astype(np.int64) if episode.dtype.kind in "iu" else episode,
        "step": (np.concatenate(steps) if steps else np.zeros(0)).astype(np.int32),
    }
    for col, e in zip(fired, rules):
        cols[e.id] = np.concatenate(col) if col else np.zeros(0, bool)
    return pa.table(cols)


def long_form(wide: pa.Table, rules: Sequence[Registered]) -> pa.Table:
    """One row per fired (stack, rule), sorted by episode, step and rule order."""
    parts = []
    for order, e in enumerate(rules):
        hit = wide.filter(wide.column(e.id))
        n = hit.num_rows
        parts.append(pa.table({
            "episode": hit.column("episode"),
            "step": hit.column("step"),
            "rule_id": pa.array([e.id] * n, pa.string()),
            "rule_version": pa.array(np.full(n, e.rule.version, np.int32)),
            "command": pa.array([e.rule.command] * n, pa.string()),
            "_order": pa.array(np.full(n, order, np.int32)),
        }))
    table = pa.concat_tables(parts) if parts else pa.table({})
    return table.sort_by([("episode", "ascending"), ("step", "ascending"),
                          ("_order", "ascending")]).drop_columns(["_order"])


def labels_fingerprint_for(rules: Sequence[Registered], info: dict[str, Any]) -> str:
    """The labels fingerprint of ``rules`` on the source ``info`` describes (its dataset
    fingerprint; the whole ``info`` for a source without one): same rules (id, version, code) on
    the same dataset ⇒ same fingerprint ⇒ resumable."""
    return labels_fingerprint(info.get("fingerprint", info),
                              [(e.id, e.rule.version, e.code_sha256) for e in rules])


def labels_fingerprint(dataset_fingerprint: Any, rules: Sequence[tuple[Any, ...]]) -> str:
    """The labels fingerprint, from the dataset fingerprint and (id, version, code sha256) per
    rule, as a label record lists them."""
    doc = {"format": FORMAT_VERSION, "dataset": dataset_fingerprint,
           "rules": [list(r) for r in rules]}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def write_part(unit: WorkUnit, rules: Sequence[Registered], keys: Sequence[str], batch_size: int,
               path: Path, on_batch: Callable[[int], None] | None = None) -> None:
    """Label one unit and write its part atomically at ``path``."""
    write_table(label_batches(unit.batches(batch_size, keys), rules, on_batch=on_batch), path)
    write_sums(part_sums(path), [path])


def parts_run(state: Path) -> str | None:
    """The labels fingerprint of the run a parts folder belongs to (its ``state.json``); None if
    it has none sc2data can read, so its parts are not resumed."""
    try:
        record = loads(state.read_text())
    except (OSError, ValueError):
        return None
    run = record.get("fingerprint") if isinstance(record, dict) else None
    return run if isinstance(run, str) else None


def part_sums(part: Path) -> Path:
    """Where a label part's sha256 is recorded (a resumed run keeps only intact parts)."""
    return part.with_name(part.name + ".sha256")


def pc_sum(col: pa.ChunkedArray) -> int:
    """Number of true values in a bool column."""
    return int(sum(np.count_nonzero(c.to_numpy(zero_copy_only=False)) for c in col.chunks))


def null_multi(wide: pa.Table, rules: Sequence[Registered]) -> tuple[int, int]:
    if not rules or wide.num_rows == 0:
        return 0, 0
    hits = np.zeros(wide.num_rows, np.int32)
    for e in rules:
        hits += wide.column(e.id).to_numpy(zero_copy_only=False)
    return int(np.count_nonzero(hits)), int(np.count_nonzero(hits > 1))
