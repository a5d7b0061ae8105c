"""Label a dataset's stacks with rules: which stacks satisfy which command.

Output, in the dataset folder:

* ``labels.parquet`` — one row per (stack, rule) that fired: ``episode``, ``step``, ``rule_id``
  (the command's id), ``rule_version``, ``command`` (its canonical text).
* ``stack_labels.parquet`` — one row per labelled stack: ``episode``, ``step`` and one bool column
  per rule id. It is how the pair stage finds *null* stacks (no column true) and checks that a
  mismatched state does not in fact satisfy a command; ``labels.parquet`` is its long form.

Both carry the same JSON under the Parquet metadata key ``sc2data.labels``: the rules' ids,
versions, texts, sources and code hashes, the dataset they came from, the counts and a
fingerprint; :func:`read_labels` refuses a pair of files whose fingerprints differ.

The work is cut into *units* (one per dataset shard). Each finished unit is written, atomically,
as a part under ``.labels-parts/``; a rerun after an interruption skips finished parts, as long as
the rules (id, version, code) and the dataset are the same. The final files are written under a
temporary name and renamed into place, so a failure never leaves a half-written labels file.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import hashlib
import json
import os
import re
import shutil
import socket
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from sc2data.errors import Sc2DataError
from sc2data.labels.registry import Registered, call, check_output
from sc2data.schema import Schema, StackBatch

LABELS_FILE = "labels.parquet"
STACKS_FILE = "stack_labels.parquet"
PARTS_DIR = ".labels-parts"
LOCK_FILE = ".labels.lock"
META_KEY = b"sc2data.labels"
FORMAT_VERSION = 1

READ_STACKS = 4096
"""Stacks read from a dataset at once; ``--batch-size`` stacks at a time go through the rules."""
DEFAULT_BATCH = 256
"""Stacks per rule call: small enough that a building rule's temporaries stay in cache."""

Batches = Iterable[tuple[np.ndarray, np.ndarray, StackBatch]]
"""``(episode ids, steps, StackBatch)`` triples, as ``Dataset.iter_batches`` yields them."""
UnitRunner = Callable[[Sequence[tuple["Unit", Path]], Sequence[str], int, Any], None]
"""Labels units elsewhere than in this process (Ray tasks: ``sc2data.scaleout.driver.RayUnits``):
``runner([(unit, part path), …], keys, batch_size, bar)``, each through :func:`write_part`."""


@dataclass(frozen=True)
class Unit:
    """One resumable piece of labelling work, typically one shard."""

    key: str
    """Stable and unique within the dataset; changes when the unit's content changes."""
    stacks: int
    """How many stacks it yields (for the progress bar)."""
    batches: Callable[[int, Sequence[str]], Batches]
    """``batches(batch_size, keys)``: its stacks, reading only ``keys``."""


@dataclass(frozen=True)
class Source:
    """What is labelled: the units, the schema they share, and a description for provenance."""

    units: Sequence[Unit]
    schema: Schema
    info: dict[str, Any] = field(default_factory=dict)
    """JSON-able description of the dataset (path, fingerprint, …), stored with the labels."""


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


# -- the pure core ---------------------------------------------------------------------------------

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


# -- the resumable driver --------------------------------------------------------------------------

def fingerprint(rules: Sequence[Registered], info: dict[str, Any]) -> str:
    """Same rules (id, version, code) on the same dataset ⇒ same fingerprint ⇒ resumable."""
    doc = {"format": FORMAT_VERSION, "dataset": info.get("fingerprint", info),
           "rules": [(e.id, e.rule.version, e.code_sha256) for e in rules]}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def _part_name(key: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", key)[:80]
    return f"{safe}-{hashlib.sha1(key.encode()).hexdigest()[:12]}.parquet"


def _write_atomic(table: pa.Table, path: Path) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        pq.write_table(table, tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _with_meta(table: pa.Table, meta: dict[str, Any]) -> pa.Table:
    return table.replace_schema_metadata({META_KEY: json.dumps(meta).encode()})


def write_part(unit: Unit, rules: Sequence[Registered], keys: Sequence[str], batch_size: int,
               path: Path, on_batch: Callable[[int], None] | None = None) -> None:
    """Label one unit and write its part atomically at ``path``."""
    _write_atomic(label_batches(unit.batches(batch_size, keys), rules, on_batch=on_batch), path)


def label(source: Source, rules: Sequence[Registered], out_dir: Path | str, *,
          batch_size: int = DEFAULT_BATCH, progress: bool | None = None,
          run_units: UnitRunner | None = None) -> LabelSummary:
    """Label every unit of ``source`` with ``rules`` into ``out_dir``; resumes finished units.

    One run at a time per folder (a lock file); an unwritable folder is a one-line error.
    ``run_units`` labels the units instead of this process (``sc2data.scaleout.driver``).
    """
    out = Path(out_dir)
    if batch_size < 1:
        raise Sc2DataError(f"--batch-size must be at least 1, not {batch_size}")
    if not rules:
        raise Sc2DataError("no rules to label with")
    check_requirements(rules, source.schema, f"the dataset at {out}")
    fp = fingerprint(rules, source.info)
    done = _existing(out, fp)
    if done is not None:
        return done
    try:
        out.mkdir(parents=True, exist_ok=True)
        with _lock(out):
            return _run(source, rules, out, fp, batch_size, progress, run_units)
    except OSError as e:
        raise Sc2DataError(f"cannot write labels in {out}: {e.strerror or e}; check the folder "
                           f"is writable and has space") from e


@contextlib.contextmanager
def _lock(out: Path) -> Iterator[None]:
    with open(out / LOCK_FILE, "a+b") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise Sc2DataError(f"another sc2data label is running on {out}; wait for it to "
                               f"finish") from None
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _run(source: Source, rules: Sequence[Registered], out: Path, fp: str, batch_size: int,
         progress: bool | None, run_units: UnitRunner | None = None) -> LabelSummary:
    from sc2data.progress import bar as progress_bar
    from sc2data.provenance import versions

    keys = required_keys(rules, source.schema)
    parts = out / PARTS_DIR
    state = parts / "state.json"
    if parts.is_dir() and (not state.is_file() or json.loads(state.read_text()).get(
            "fingerprint") != fp):
        shutil.rmtree(parts)  # parts of other rules or another dataset: not resumable
    parts.mkdir(parents=True, exist_ok=True)
    if not state.is_file():
        tmp = state.with_name(f".state.json.tmp-{os.getpid()}")
        tmp.write_text(json.dumps({"fingerprint": fp}))
        os.replace(tmp, state)

    names = [_part_name(u.key) for u in source.units]
    if len(set(names)) != len(names):
        raise Sc2DataError("the dataset's shards do not have unique keys; cannot label it")
    finished = {n for n in names if (parts / n).is_file()}
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
    any_count, multi = _null_multi(wide, rules)
    meta = {
        "format": FORMAT_VERSION,
        "fingerprint": fp,
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
    _write_atomic(_with_meta(wide, meta), out / STACKS_FILE)
    _write_atomic(_with_meta(long_form(wide, rules), meta), out / LABELS_FILE)
    shutil.rmtree(parts, ignore_errors=True)
    return _summary(out, meta, resumed=len(finished))


def pc_sum(col: pa.ChunkedArray) -> int:
    """Number of true values in a bool column."""
    return int(sum(np.count_nonzero(c.to_numpy(zero_copy_only=False)) for c in col.chunks))


def _null_multi(wide: pa.Table, rules: Sequence[Registered]) -> tuple[int, int]:
    if not rules or wide.num_rows == 0:
        return 0, 0
    hits = np.zeros(wide.num_rows, np.int32)
    for e in rules:
        hits += wide.column(e.id).to_numpy(zero_copy_only=False)
    return int(np.count_nonzero(hits)), int(np.count_nonzero(hits > 1))


def _summary(out: Path, meta: dict[str, Any], resumed: int = 0,
             up_to_date: bool = False) -> LabelSummary:
    return LabelSummary(path=out / LABELS_FILE, stacks=meta["stacks"], counts=meta["counts"],
                        commands={r["id"]: r["command"] for r in meta["rules"]},
                        null=meta["null"], multi=meta["multi"], resumed_units=resumed,
                        up_to_date=up_to_date)


def _existing(out: Path, fp: str) -> LabelSummary | None:
    """The summary of labels already made by the same rules from the same data, if any."""
    try:
        meta = read_meta(out)
        other = json.loads((pq.read_schema(out / STACKS_FILE).metadata or {}).get(META_KEY, b"{}"))
    except (Sc2DataError, OSError, ValueError):
        return None
    if meta.get("fingerprint") != fp or other.get("created") != meta.get("created") or \
            other.get("fingerprint") != fp:
        return None
    return _summary(out, meta, up_to_date=True)


# -- reading ---------------------------------------------------------------------------------------

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


# -- labelling units in other processes ----------------------------------------------------------
@functools.lru_cache(maxsize=4)
def _rules_and_source(data: str, selection: tuple[Any, Any, Any], run: str
                      ) -> tuple[Sequence[Registered], Source]:
    """Loaded once per worker process and run (``run``: the run's fingerprint, so a process
    that outlives a run, as Ray's do, reloads for the next)."""
    from sc2data.labels.registry import load_registry

    include, exclude, rules_dir = selection
    return load_registry(rules_dir).select(include, exclude), dataset_source(data)


def label_unit(data: str, selection: tuple[Any, Any, Any], unit_key: str, part: str,
               keys: Sequence[str], batch_size: int, report: Callable[[int], None]) -> None:
    """Label unit ``unit_key`` of the dataset at ``data`` into ``part``, away from the process
    that runs :func:`label` (a worker process, a Ray task): the rules are loaded from
    ``selection`` = (include, exclude, rules_dir) and checked to be the run's (its parts
    folder's ``state.json``), then the unit is written with :func:`write_part`."""
    include, exclude, rules_dir = selection
    run = str(json.loads((Path(part).parent / "state.json").read_text()).get("fingerprint"))
    rules, source = _rules_and_source(data, (None if include is None else tuple(include),
                                             tuple(exclude), rules_dir), run)
    if fingerprint(rules, source.info) != run:
        raise Sc2DataError(f"{socket.gethostname()} sees other rules or other data than the run "
                           f"that started this label; install the same sc2data and rule "
                           f"plugins on every node and share the dataset folder")
    unit = next(u for u in source.units if u.key == unit_key)
    write_part(unit, rules, keys, batch_size, Path(part), on_batch=report)


def _unit_job(data: str, selection: tuple[Any, Any, Any], units: Sequence[tuple[str, str]],
              keys: Sequence[str], batch_size: int, i: int, report: Callable[[int], None]
              ) -> None:
    label_unit(data, selection, units[i][0], units[i][1], keys, batch_size, report)


@dataclass(frozen=True)
class LocalUnits:
    """A unit runner: label units in ``workers`` local processes (as rollout's workers run)."""

    workers: int
    data: Path
    selection: tuple[Any, Any, Any]

    def __call__(self, todo: Sequence[tuple[Unit, Path]], keys: Sequence[str], batch_size: int,
                 bar: Any) -> None:
        from sc2data.workers import run_parallel

        if not todo:
            return
        units = [(unit.key, str(path)) for unit, path in todo]
        job = functools.partial(_unit_job, str(Path(self.data).resolve()), self.selection, units,
                                tuple(keys), batch_size)
        parts = todo[0][1].parent
        try:
            run_parallel(job, list(range(len(units))), self.workers, parts, bar.update,
                         lambda i: units[i][0].split(":")[0], what="label")
        except BaseException:  # a worker stopped mid-write leaves its temporary part behind
            for stale in parts.glob(".*.tmp-*"):
                stale.unlink(missing_ok=True)
            raise


# -- the dataset door ------------------------------------------------------------------------------

def dataset_source(path: Path | str) -> Source:
    """A :class:`Source` over the rolled-out dataset at ``path``: one unit per shard, keyed by the
    shard's name and sha256 (a re-rolled shard is relabelled), reading only the keys asked for."""
    from sc2data import open_dataset

    ds = open_dataset(path)
    index = ds.index.to_pydict()
    shards: dict[str, dict[str, Any]] = {}
    for shard, sha, episode, n in zip(index["shard"], index["shard_sha256"], index["episode"],
                                      index["n_steps"]):
        entry = shards.setdefault(shard, {"sha256": sha, "episodes": []})
        entry["episodes"].append((int(episode), int(n)))

    def reader(episodes: list[tuple[int, int]]) -> Callable[[int, Sequence[str]], Batches]:
        ep = np.concatenate([np.full(n, e, np.int64) for e, n in episodes]) if episodes else \
            np.zeros(0, np.int64)
        st = np.concatenate([np.arange(n, dtype=np.int64) for _, n in episodes]) if episodes \
            else np.zeros(0, np.int64)

        def batches(batch_size: int, keys: Sequence[str]) -> Batches:
            # Read big (chunk decoding amortises), label small (the rules' temporaries stay in
            # cache): sub-batches are views of one read.
            step = max(batch_size, READ_STACKS)
            for i in range(0, len(ep), step):
                e, s = ep[i:i + step], st[i:i + step]
                big = ds.read(e, s, keys)
                for j in range(0, len(e), batch_size):
                    part = {k: a[j:j + batch_size] for k, a in big.arrays.items()}
                    yield e[j:j + batch_size], s[j:j + batch_size], StackBatch(part, big.schema)
        return batches

    units = [Unit(key=f"{name}:{info['sha256']}", stacks=sum(n for _, n in info["episodes"]),
                  batches=reader(sorted(info["episodes"])))
             for name, info in sorted(shards.items())]
    fingerprint = hashlib.sha256(json.dumps(
        [ds.schema.to_dict(), sorted((u.key for u in units))]).encode()).hexdigest()
    info = {"path": str(Path(path).resolve()), "fingerprint": fingerprint,
            "episodes": int(len(ds.episode_ids)), "stacks": len(ds),
            "settings": ds.settings, "schema": ds.schema.to_dict()}
    return Source(units, ds.schema, info)


def label_dataset(data: Path | str, *, include: Sequence[str] | None = None,
                  exclude: Sequence[str] = (), rules_dir: Path | str | None = None,
                  batch_size: int = DEFAULT_BATCH, progress: bool | None = None,
                  workers: int = 1, run_units: UnitRunner | None = None) -> LabelSummary:
    """``sc2data label``: load and select rules, open the dataset, label it into its folder,
    in ``workers`` processes (one shard at a time each) or through ``run_units``."""
    from sc2data.labels.registry import load_registry

    if workers < 1:
        raise Sc2DataError(f"workers must be at least 1, not {workers}")
    rules = load_registry(rules_dir).select(include, exclude)
    if run_units is None and workers > 1:
        selection = (None if include is None else tuple(include), tuple(exclude),
                     None if rules_dir is None else str(Path(rules_dir).resolve()))
        run_units = LocalUnits(workers, Path(data), selection)
    return label(dataset_source(data), rules, data, batch_size=batch_size, progress=progress,
                 run_units=run_units)
