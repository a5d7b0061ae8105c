"""``sc2data label``: mark which stacks of a dataset satisfy which command, resumably.

The work is cut into *units* (one per dataset shard, :mod:`sc2data.labels.source`). Each finished
unit is written, atomically, as a part under ``.labels-parts/``; a rerun after an interruption
skips finished parts, as long as the rules (id, version, code) and the dataset are the same. The
final files (:mod:`sc2data.labels.store`) are written under a temporary name and renamed into
place, so a failure never leaves a half-written labels file. One run at a time per folder.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from sc2data.ground.errors import Sc2DataError, reason
from sc2data.ground.files import FolderLock, write_atomic
from sc2data.ground.progress import Bar
from sc2data.ground.progress import bar as progress_bar
from sc2data.ground.provenance import versions
from sc2data.ground.resume import STATE, differences
from sc2data.labels.apply import (
    check_requirements,
    label_batches,
    labels_fingerprint_for,
    long_form,
    null_multi,
    part_sums,
    parts_run,
    pc_sum,
    required_keys,
    write_part,
)
from sc2data.labels.registry import Registered, load_registry
from sc2data.labels.source import Source, WorkUnit, dataset_source
from sc2data.labels.store import (
    FORMAT_VERSION,
    LABELS_FILE,
    STACKS_FILE,
    check_sums,
    file_meta,
    read_meta,
    write_labels,
)

PARTS_DIR = ".labels-parts"
DEFAULT_BATCH = 256
"""Stacks per rule call: small enough that a building rule's temporaries stay in cache."""

UnitRunner = Callable[[Sequence[tuple[WorkUnit, Path]], Sequence[str], int, Bar], None]
"""Labels units elsewhere than in this process (Ray tasks: ``sc2data.scaleout.driver.RayUnits``):
``runner([(unit, part path), …], keys, batch_size, bar)``, each through :func:`write_part`."""

@dataclass(frozen=True)
class LabelSummary:
    """Counts of a finished labelling run."""

    path: Path
    stacks: int
    counts: dict[str, int]
    commands: dict[str, str]
    null: int
    multi: int
    resumed_units: int = 0
    up_to_date: bool = False

    def table(self) -> str:
        """Counts and fire rates per command, then the null and overlap rates."""
        rows = [(self.commands[i], i, n) for i, n in self.counts.items()]
        rows += [("(null: no rule fired)", "", self.null),
                 ("(two or more rules fired)", "", self.multi)]
        w0 = max(len(r[0]) for r in rows + [("command", "", 0)])
        w1 = max(len(r[1]) for r in rows + [("", "rule id", 0)])

        def rate(n: int) -> str:
            return f"{100 * n / self.stacks:7.3f}%" if self.stacks else "      -"

        lines = [f"{'command':<{w0}}  {'rule id':<{w1}}  {'stacks':>10}  {'rate':>8}"]
        lines += [f"{c:<{w0}}  {i:<{w1}}  {n:>10,}  {rate(n)}" for c, i, n in rows]
        lines.append(f"{self.stacks:,} stacks labelled → {self.path}")
        return "\n".join(lines)


def _part_name(key: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", key)[:80]
    return f"{safe}-{hashlib.sha1(key.encode()).hexdigest()[:12]}.parquet"


def label(source: Source, rules: Sequence[Registered], out_dir: Path | str, *,
          batch_size: int = DEFAULT_BATCH, progress: bool | None = None,
          run_units: UnitRunner | None = None, overwrite: bool = False) -> LabelSummary:
    """Label every unit of ``source`` with ``rules`` into ``out_dir``; resumes finished units.

    Labels of another set of rules are never replaced silently (a later ``pair`` would miss the
    rules left out): that takes ``overwrite``. Labels of the same rules whose code or data
    changed are stale, and are relabelled.

    One run at a time per folder (a lock file); an unwritable folder is a one-line error.
    ``run_units`` labels the units instead of this process (``sc2data.scaleout.driver``).
    """
    out = Path(out_dir)
    if batch_size < 1:
        raise Sc2DataError(f"--batch-size must be at least 1, not {batch_size}")
    if not rules:
        raise Sc2DataError("no rules to label with")
    check_requirements(rules, source.schema, f"the dataset at {out}")
    labels_fp = labels_fingerprint_for(rules, source.info)
    done = _existing(out, labels_fp)
    if done is not None:
        return done
    _check_replacing(out, rules, overwrite)
    try:
        out.mkdir(parents=True, exist_ok=True)
        with FolderLock(out, "label"):
            return _run(source, rules, out, labels_fp, batch_size, progress, run_units)
    except OSError as e:
        raise Sc2DataError(f"cannot write labels in {out}: {reason(e)}; check the folder "
                           f"is writable and has space") from e


def _run(source: Source, rules: Sequence[Registered], out: Path, labels_fp: str, batch_size: int,
         progress: bool | None, run_units: UnitRunner | None = None) -> LabelSummary:

    keys = required_keys(rules, source.schema)
    parts = out / PARTS_DIR
    state = parts / STATE
    if parts.is_dir() and parts_run(state) != labels_fp:
        shutil.rmtree(parts)  # parts of other rules or another dataset: not resumable
    parts.mkdir(parents=True, exist_ok=True)
    if not state.is_file():
        write_atomic(state, json.dumps({"fingerprint": labels_fp}).encode())

    names = [_part_name(u.key) for u in source.units]
    if len(set(names)) != len(names):
        raise Sc2DataError("the dataset's shards do not have unique keys; cannot label it")
    finished = {n for n in names if _intact(parts / n)}
    total = sum(u.stacks for u in source.units)
    with progress_bar(total, desc="label", unit="stack", show=progress) as bar:
        bar.update(sum(u.stacks for u, n in zip(source.units, names) if n in finished))
        todo = [(u, parts / n) for u, n in zip(source.units, names) if n not in finished]
        if run_units is not None:
            run_units(todo, keys, batch_size, bar)
        else:
            for unit, path in todo:
                write_part(unit, rules, keys, batch_size, path, on_batch=bar.update)
    wide = pa.concat_tables([pq.read_table(parts / n) for n in names]) if names else \
        label_batches((), rules)
    summary_counts = {e.id: int(pc_sum(wide.column(e.id))) for e in rules}
    any_count, multi = null_multi(wide, rules)
    meta = {
        "format": FORMAT_VERSION,
        "fingerprint": labels_fp,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "dataset": source.info,
        "rules": [e.to_dict() for e in rules],
        "stacks": wide.num_rows,
        "counts": summary_counts,
        "null": wide.num_rows - any_count,
        "multi": multi,
        "versions": versions(),
    }
    # The per-stack table first, the long one last: read_labels checks they belong together.
    write_labels(out, wide, long_form(wide, rules), meta)
    shutil.rmtree(parts, ignore_errors=True)
    return _summary(out, meta, resumed=len(finished))


def _intact(part: Path) -> bool:
    """A finished part whose bytes are those recorded when it was written; a damaged one (and its
    record) is removed, so the unit is labelled again."""
    if not part.is_file():
        return False
    try:
        check_sums(part_sums(part), "")
        return True
    except Sc2DataError:
        part.unlink(missing_ok=True)
        part_sums(part).unlink(missing_ok=True)
        return False


def _check_replacing(out: Path, rules: Sequence[Registered], overwrite: bool) -> None:
    """Refuse to replace intact labels of other rules unless asked."""
    if overwrite or not (out / LABELS_FILE).exists():
        return
    try:
        old = [r["id"] for r in read_meta(out)["rules"]]
    except Sc2DataError:
        return  # damaged labels: relabelling them is the remedy
    new = [e.id for e in rules]
    if differences({"rules": sorted(old)}, {"rules": sorted(new)}):
        raise Sc2DataError(f"{out} already has labels of the rules {', '.join(old)}; this run "
                           f"labels with {', '.join(new)}. Pass --overwrite to replace them (a "
                           f"recipe naming a rule left out then cannot be paired)")


def _summary(out: Path, meta: dict[str, Any], resumed: int = 0,
             up_to_date: bool = False) -> LabelSummary:
    return LabelSummary(path=out / LABELS_FILE, stacks=meta["stacks"], counts=meta["counts"],
                        commands={r["id"]: r["command"] for r in meta["rules"]},
                        null=meta["null"], multi=meta["multi"], resumed_units=resumed,
                        up_to_date=up_to_date)


def _existing(out: Path, labels_fp: str) -> LabelSummary | None:
    """The summary of labels already made by the same rules from the same data, if any."""
    try:
        meta = read_meta(out)
        other = file_meta(out / STACKS_FILE)
    except Sc2DataError:
        return None
    if meta.get("fingerprint") != labels_fp or other.get("created") != meta.get("created") or \
            other.get("fingerprint") != labels_fp:
        return None
    return _summary(out, meta, up_to_date=True)


def label_dataset(data: Path | str, *, include: Sequence[str] | None = None,
                  exclude: Sequence[str] = (), rules_dir: Path | str | None = None,
                  batch_size: int = DEFAULT_BATCH, progress: bool | None = None,
                  workers: int = 1, run_units: UnitRunner | None = None,
                  overwrite: bool = False) -> LabelSummary:
    """``sc2data label``: load and select rules, open the dataset, label it into its folder,
    in ``workers`` processes (one shard at a time each) or through ``run_units``."""
    if workers < 1:
        raise Sc2DataError(f"workers must be at least 1, not {workers}")
    rules = load_registry(rules_dir).select(include, exclude)
    if run_units is None and workers > 1:
        selection = (None if include is None else tuple(include), tuple(exclude),
                     None if rules_dir is None else str(Path(rules_dir).resolve()))
        from sc2data.labels.remote import LocalUnits

        run_units = LocalUnits(workers, Path(data), selection)
    return label(dataset_source(data), rules, data, batch_size=batch_size, progress=progress,
                 run_units=run_units, overwrite=overwrite)
