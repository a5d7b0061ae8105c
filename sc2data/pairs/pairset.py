"""``sc2data pair``: labels + recipe → ``pairs.parquet``, ``pairset.json`` and packed splits.

The output folder is the trainer's input (``docs/pairset.md``). It is built under a temporary
name and renamed into place when complete, so an interrupted run never leaves a pair set that
looks finished; a folder already built from the same recipe, labels and data is kept as it is.

A recipe of several sources (``[sources.NAME]``) reads each from ``DATA/NAME``. Every source is
checked before anything is written — it exists and is a labelled dataset of the recipe's rules
(the same rules' code in all), rolled out as its source says, its shards the bytes its index
recorded, one schema for all — and a source with too few states is named in the one-line error
with the episodes it needs.
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from sc2data.data.dataset import Dataset, open_dataset, read_dataset_record, read_index
from sc2data.ground.errors import Sc2DataError, reason
from sc2data.ground.files import (
    PARTIAL,
    FolderLock,
    check_out,
    fsync_path,
    publish,
    sha256_file,
    write_atomic,
)
from sc2data.ground.formats import PAIRSET, loads
from sc2data.ground.progress import Bar
from sc2data.ground.progress import bar as progress_bar
from sc2data.ground.provenance import versions
from sc2data.ground.recipe import Recipe, RolloutSpec
from sc2data.ground.resume import differences
from sc2data.ground.vocab import SPLITS
from sc2data.labels.apply import labels_fingerprint
from sc2data.pairs.draw import Labelled, NotEnoughStates, SourceShortage, build_pairs
from sc2data.pairs.layout import (
    META_FILE,
    PACKED_DIR,
    PAIRS_FILE,
    check_content,
    content_files,
    packed_path,
    pairset_fingerprint,
)
from sc2data.pairs.packed import PackedWriter
from sc2data.schema import StackBatch

READ_BATCH = 1024
"""Stacks read from the rollout shards per call while packing."""


@dataclass(frozen=True)
class PairsetSummary:
    """What ``sc2data pair`` made (or found already made)."""

    out: Path
    counts: dict[str, dict[str, int]]
    """split → kind → pairs."""
    states: dict[str, int]
    seconds: float
    up_to_date: bool = False

    def table(self) -> str:
        """A fixed-width summary: pairs per split and kind, states per split."""
        kinds = ("matched", "mismatched", "null")
        lines = [f"{'split':<6} {'matched':>9} {'mismatched':>11} {'null':>8} {'pairs':>9} "
                 f"{'states':>8}"]
        for s in SPLITS:
            c = self.counts.get(s, {})
            lines.append(f"{s:<6} " + " ".join(f"{c.get(k, 0):>{w},}" for k, w in
                                              zip(kinds, (9, 11, 8))) +
                         f" {sum(c.values()):>9,} {self.states.get(s, 0):>8,}")
        return "\n".join(lines)


def check_texts(recipe: Recipe, rule_commands: dict[str, str]) -> None:
    """A command's canonical text is its rule's: the labels record the rule's ``command``, the pairs
    the recipe's ``text``, and a model trained on one but read with the other would silently
    mean another thing. Other wordings belong in the recipe's ``train_paraphrases`` (trained on)
    or ``paraphrases`` (held out)."""
    for c in recipe.commands:
        rule_text = rule_commands.get(c.id)
        if rule_text is not None and c.text != rule_text:
            raise Sc2DataError(f"recipe {recipe.name!r}: command {c.id} has text {c.text!r}, but "
                               f"rule {c.id} says {rule_text!r}; use the rule's text in the "
                               f"recipe and list other wordings as train_paraphrases or "
                               f"paraphrases")


def check_rollout(recipe: Recipe, settings: dict[str, Any], data: Path,
                  spec: RolloutSpec | None = None) -> None:
    """The data was rolled out as the recipe's ``[rollout]`` (or its source's ``spec``) says
    (backend, agent, layers, step_mul): a pair set records the recipe as its provenance, so the
    claim must be true."""
    spec = spec or recipe.rollout
    differ = [f"{k} {settings.get(k)!r} (recipe: {getattr(spec, k)!r})"
              for k in ("env", "agent", "layers", "step_mul")
              if settings.get(k) != getattr(spec, k)]
    if differ:
        raise Sc2DataError(f"{data} was not rolled out as recipe {recipe.name!r} says: "
                           f"{'; '.join(differ)}; pair it with a recipe that describes it, or "
                           f"build the recipe's own data with sc2data build")


def check_current(labels_meta: dict[str, Any], data: Path) -> None:
    """The labels are of the data the folder holds now, not of what it held before it grew (or
    was rolled out again): pairs drawn from them would miss the new episodes."""
    from sc2data.labels.source import dataset_source

    if labels_meta.get("dataset", {}).get("fingerprint") != \
            dataset_source(data).info["fingerprint"]:
        raise Sc2DataError(f"the labels in {data} are of other data than it holds now (it grew, "
                           f"or was rolled out again); relabel it: sc2data label {data}")


def labelled_stacks(recipe: Recipe, data: Path, spec: RolloutSpec | None = None
                    ) -> tuple[Labelled, dict[str, Any]]:
    """Every stack of ``data`` with the recipe's rules' verdicts, from ``sc2data label``'s files
    (``spec``: the rollout settings the data must have, default the recipe's ``[rollout]``)."""
    from sc2data.labels.store import read_labels

    labels = read_labels(data)
    ids = [r["id"] for r in labels.meta["rules"]]
    missing = [c.id for c in recipe.commands if c.id not in ids]
    if missing:
        raise Sc2DataError(f"the labels in {data} have no rule {', '.join(missing)} (labelled "
                           f"with: {', '.join(ids)}); relabel with sc2data label {data} --rules "
                           f"{','.join(recipe.rule_ids)}")
    check_texts(recipe, {r["id"]: r["command"] for r in labels.meta["rules"]})
    check_rollout(recipe, labels.meta.get("dataset", {}).get("settings", {}), data, spec)
    check_current(labels.meta, data)
    t = labels.stacks
    fires = np.stack([t[c.id].to_numpy(zero_copy_only=False) for c in recipe.commands], axis=1)
    data_labelled = Labelled(t["episode"].to_numpy().astype(np.int64),
                             t["step"].to_numpy().astype(np.int32), fires.astype(bool))
    return data_labelled, labels.meta


def grow_command(data: Path, episodes: int, rules: list[dict[str, Any]]) -> str:
    """The shell command that grows dataset ``data`` to ``episodes`` episodes (its other
    settings are the folder's) and labels it again with the same ``rules``."""
    from sc2data.labels.registry import load_registry

    q = shlex.quote(str(data))
    dirs = sorted({str(Path(r["source"][len("file "):]).parent) for r in rules
                   if str(r.get("source", "")).startswith("file ")})
    options = f" --rules-dir {shlex.quote(dirs[0])}" if dirs else ""
    ids = [r["id"] for r in rules]
    try:
        default = load_registry(dirs[0] if dirs else None).ids
    except Sc2DataError:
        default = []
    if sorted(default) != sorted(ids):
        options += f" --rules {','.join(ids)}"
    return f"sc2data rollout --out {q} --episodes {episodes} && sc2data label {q}{options}"


def _identity(recipe: Recipe, labels_meta: dict[str, Any],
              sources: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """What decides a pair set's content: the recipe and the labels it was drawn from (their
    labels fingerprint: the same rules' code on the same shards, so the same labels; never when they
    were made, so a relabel with identical content keeps the pair set); with several
    ``sources`` (their labels' records), every source's labels by name."""
    labels = labels_meta.get("fingerprint") if sources is None else \
        {s.name: m.get("fingerprint") for s, m in zip(recipe.sources, sources)}
    identity = {"recipe": recipe.to_dict(), "labels": labels}
    return json.loads(json.dumps(identity))  # as it reads back from pairset.json


def _stored(out: Path) -> dict[str, Any] | str:
    """``out``'s pair-set record, or why there is none sc2data can read."""
    meta_path = out / META_FILE
    if not meta_path.is_file():
        return f"no {META_FILE}"
    try:
        meta = loads(meta_path.read_text())
        PAIRSET.check(meta, meta_path)
    except (OSError, ValueError, Sc2DataError) as e:
        return str(e)
    return meta


def _same(meta: dict[str, Any], identity: dict[str, Any]) -> bool:
    """The record was drawn from this recipe and these labels: only the fields that decide the
    content count (an earlier sc2data also stored when the labels were made, ``labels_created``)."""
    stored = meta.get("identity")
    return isinstance(stored, dict) and not differences(stored, identity, keys=identity)


def _other(out: Path, data: Path, recipe: Recipe, identity: dict[str, Any],
           labels_meta: dict[str, Any]) -> str:
    """Why ``out`` (not empty) is not the pair set of ``identity``, in words, with what to do."""
    remedy = "delete it to draw it again, or choose another --out"
    meta = _stored(out)
    if isinstance(meta, str):
        return f"{out} already holds something other than a pair set ({meta}); choose another " \
               f"--out or delete it"
    stored = meta.get("identity") if isinstance(meta.get("identity"), dict) else {}
    old, new = stored.get("recipe"), identity["recipe"]
    by = f" (written by sc2data {meta.get('versions', {}).get('sc2data', '?')})"
    if not isinstance(old, dict) or old.get("name") != recipe.name:
        name = old.get("name") if isinstance(old, dict) else meta.get("recipe_name")
        return f"{out} holds the pair set of recipe {name!r}, not {recipe.name!r}{by}; {remedy}"
    if old != new:
        differ = differences(old, new)
        return f"{out} holds a pair set of another version of recipe {recipe.name!r} (differs " \
               f"in: {', '.join(differ)}){by}; {remedy}"
    code = {r.get("id"): r.get("code_sha256") for r in meta.get("labels", {}).get("rules") or []
            if isinstance(r, dict)}
    changed = [r["id"] for r in labels_meta.get("rules", []) if code.get(r["id"], r.get(
        "code_sha256")) != r.get("code_sha256")]
    why = f": the code of rule(s) {', '.join(changed)} changed" if changed else ""
    return f"{out} was drawn for recipe {recipe.name!r} from other labels than {data} holds " \
           f"now (relabelled since{why}){by}; {remedy}"


def _relabelled(out: Path, identity: dict[str, Any], labels_meta: dict[str, Any],
                pairs: pa.Table) -> dict[str, Any] | None:
    """``out``'s record, brought up to date, if it is this recipe's pair set drawn from labels
    that were remade since (another rules' code, e.g. a docstring) on the same shards, and the
    current labels draw exactly its pairs: the content is the same, so it is kept."""
    meta = _stored(out)
    stored = meta.get("identity") if isinstance(meta, dict) else None
    if not isinstance(meta, dict) or not isinstance(stored, dict) or \
            stored.get("recipe") != identity["recipe"]:
        return None
    rules = [(r.get("id"), r.get("version"), r.get("code_sha256"))
             for r in meta.get("labels", {}).get("rules") or [] if isinstance(r, dict)]
    dataset_fingerprint = labels_meta.get("dataset", {}).get("fingerprint")
    if labels_fingerprint(dataset_fingerprint, rules) != stored.get("labels"):
        return None  # drawn from other shards, or the record does not say
    try:
        check_content(out, str(meta["fingerprint"]))
        drawn = pq.read_table(out / PAIRS_FILE).drop_columns(["state"])
    except (Sc2DataError, OSError, KeyError, pa.ArrowException):
        return None
    if not drawn.equals(pa.concat_tables([pairs.filter(pc.equal(pairs["split"], s))
                                          for s in SPLITS])):
        return None
    meta.update(identity=identity, labels={"fingerprint": labels_meta.get("fingerprint"),
                                           "rules": labels_meta.get("rules")})
    write_atomic(out / META_FILE, json.dumps(meta, indent=2, default=str).encode())
    return meta


def _existing(out: Path, identity: dict[str, Any]) -> dict[str, Any] | None:
    meta = _stored(out)
    if isinstance(meta, str) or not _same(meta, identity):
        return None
    try:
        check_content(out, str(meta.get("fingerprint")))
    except Sc2DataError:  # ours, but damaged: rebuilt from scratch
        shutil.rmtree(out)
        return None
    return meta


def _pack_split(ds: Dataset | Sequence[Dataset], split: str, pairs: pa.Table, path: Path,
                seed: int, progress: Bar, names: Sequence[str] = ()) -> tuple[pa.Table, int]:
    """Copy the split's distinct stacks into ``path``; add each pair's ``state`` row.

    Rows go episode by episode, the episodes in a seeded random order and each episode's steps
    in order: reads stay nearly sequential (an episode's chunks are decoded once), while any
    block of rows mixes several episodes from anywhere in the data for the trainer to shuffle.
    With several sources (``ds`` one dataset per name of ``names``, the pairs' ``source``
    column naming them) an "episode" is a (source, episode) pair.
    """
    datasets = list(ds) if isinstance(ds, Sequence) else [ds]
    episode = pairs["episode"].to_numpy()
    step = pairs["step"].to_numpy().astype(np.int64)
    keys = episode * (1 << 20) + step  # episodes have far fewer than 2**20 steps
    if "source" in pairs.column_names:  # source above bit 52, episode number below it
        index = {n: i for i, n in enumerate(names)}
        source = np.array([index[n] for n in pairs["source"].to_pylist()], np.int64)
        keys = keys + (source << _SOURCE_SHIFT)
    unique, inverse = np.unique(keys, return_inverse=True)
    rng = np.random.default_rng(np.random.SeedSequence([seed, SPLITS.index(split), 0x9AC4]))
    episodes = np.unique(unique >> 20)
    rank = dict(zip(episodes.tolist(), rng.permutation(len(episodes)).tolist()))
    order = np.lexsort((unique, np.array([rank[e] for e in (unique >> 20).tolist()])))
    row_of = np.empty(len(unique), np.int64)  # row r of the file holds stack unique[order[r]]
    row_of[order] = np.arange(len(unique))
    writer = PackedWriter(path, datasets[0].schema, len(unique), attrs={"split": split})
    try:
        for start in range(0, len(unique), READ_BATCH):
            k = unique[order[start:start + READ_BATCH]]
            writer.write(_read(datasets, k))
            progress.update(len(k))
        writer.close()
    except BaseException:
        writer.abort()
        raise
    return pairs.append_column("state", pa.array(row_of[inverse], pa.int64())), len(unique)


_SOURCE_SHIFT = 52
"""Packing keys: ``source << 52 | episode << 20 | step``."""


def _read(datasets: Sequence[Dataset], k: np.ndarray) -> StackBatch:
    """The stacks of packing keys ``k``, in order, from the datasets their sources name."""
    source = k >> _SOURCE_SHIFT
    episode = (k >> 20) & ((1 << (_SOURCE_SHIFT - 20)) - 1)
    step = k & ((1 << 20) - 1)
    if len(datasets) == 1:
        return datasets[0].read(episode, step)
    arrays: dict[str, np.ndarray] = {}
    for u in np.unique(source).tolist():
        m = source == u
        for key, a in datasets[u].read(episode[m], step[m]).arrays.items():
            arrays.setdefault(key, np.empty((len(k), *a.shape[1:]), a.dtype))[m] = a
    return StackBatch(arrays, datasets[0].schema)


def _check_shards(folder: Path) -> None:
    """One line unless every shard the index lists is the bytes it recorded."""
    index = read_index(folder).to_pydict()
    for name, sha in sorted(set(zip(index["shard"], index["shard_sha256"]))):
        path = folder / name
        if not path.is_file() or sha256_file(path) != sha:
            raise Sc2DataError(f"{path} is missing, damaged or replaced (not the sha256 the index "
                               f"recorded); run sc2data verify {folder}")


def _check_sources(recipe: Recipe, data: Path) -> tuple[list[Labelled], list[dict[str, Any]]]:
    """Each of a recipe's sources (``DATA/NAME``) as labelled stacks, with its labels' record;
    a one-line error naming the first that is missing, damaged, rolled out otherwise than its
    source says, labelled by other rules' code, or of another schema than the first."""
    labelled, metas = [], []
    first: tuple[str, dict[str, Any], dict[str, Any]] | None = None
    for source in recipe.sources:
        folder = data / source.name
        try:
            if not folder.is_dir():
                raise Sc2DataError(f"{folder} does not exist; roll it out: sc2data rollout "
                                   f"--agent {source.rollout.agent} --episodes "
                                   f"{source.rollout.episodes} --out {folder}, then sc2data "
                                   f"label {folder}")
            dataset_record = read_dataset_record(folder)
            _check_shards(folder)
            found, meta = labelled_stacks(recipe, folder, source.rollout)
        except Sc2DataError as e:
            raise Sc2DataError(f"source {source.name}: {e}") from None
        rules = {r["id"]: r.get("code_sha256") for r in meta.get("rules", [])
                 if r.get("id") in recipe.rule_ids}
        if first is None:
            first = (source.name, dataset_record["schema"], rules)
        elif dataset_record["schema"] != first[1]:
            raise Sc2DataError(f"source {source.name} ({folder}) holds other layers than source "
                               f"{first[0]}; their stacks cannot be paired together: roll it out "
                               f"with the same layers")
        elif rules != first[2]:
            other = sorted(k for k in rules if rules[k] != first[2].get(k))
            raise Sc2DataError(f"source {source.name} was labelled with other code of rule(s) "
                               f"{', '.join(other)} than source {first[0]}; relabel both with "
                               f"this sc2data (sc2data label DATA)")
        labelled.append(found)
        metas.append(meta)
    return labelled, metas


def make_pairset(recipe: Recipe, data: str | os.PathLike[str], out: str | os.PathLike[str], *,
                 progress: bool | None = None) -> PairsetSummary:
    """Build the recipe's pair set from the labelled dataset ``data`` into the folder ``out``."""
    started = time.perf_counter()
    data, out = Path(data), Path(out)
    check_out(out)
    drawn = None
    if recipe.sources:
        labelled, sources = _check_sources(recipe, data)
        labels_meta = sources[0]
        drawn = _draw(recipe, labelled, data, labels_meta)  # too few states: before any lock
    else:
        read_dataset_record(data)  # the dataset's own record first, then its labels
        one, labels_meta = labelled_stacks(recipe, data)
        labelled, sources = [one], []
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise Sc2DataError(f"cannot create {out}: {reason(e)}; choose another --out") \
            from None
    # The folder is built beside its final name and renamed into place: locked from beside it,
    # by a lock file that goes with the command (nothing is left beside the pair set).
    with FolderLock(out.parent, "pair", name=f".{out.name}.lock", what=out, remove=True):
        try:
            return _make(recipe, data, out, labelled, labels_meta, started, progress,
                         sources, drawn)
        except OSError as e:
            raise Sc2DataError(f"cannot write the pair set {out}: {reason(e)}; check the "
                               f"folder is writable and has space") from None


def _draw(recipe: Recipe, labelled: list[Labelled], data: Path, labels_meta: dict[str, Any]
          ) -> pa.Table:
    """The recipe's pairs; too few states name the command that grows the data enough."""
    try:
        return build_pairs(recipe, labelled)
    except SourceShortage as e:
        grow = "; ".join(grow_command(data / name, n, labels_meta.get("rules", []))
                         for name, n in e.sources.items() if n)
        hint = str(e)[len(e.shortfall) + 2:]
        raise NotEnoughStates(e.shortfall, hint + (f": {grow}" if grow else ""), None) from None
    except NotEnoughStates as e:
        if e.episodes is None:
            raise
        command = grow_command(data, e.episodes, labels_meta.get("rules", []))
        raise NotEnoughStates(e.shortfall, f"grow the data: {command}", e.episodes) from None


def _make(recipe: Recipe, data: Path, out: Path, labelled: list[Labelled],
          labels_meta: dict[str, Any], started: float, progress: bool | None,
          sources: list[dict[str, Any]], drawn: pa.Table | None) -> PairsetSummary:
    """``make_pairset`` under its lock."""

    identity = _identity(recipe, labels_meta, sources or None)
    done = _existing(out, identity)
    if done is None and out.exists() and any(out.iterdir()):
        try:  # (kept for one source: several sources' labels are compared whole)
            done = None if sources else _relabelled(out, identity, labels_meta,
                                                    build_pairs(recipe, labelled))
        except NotEnoughStates:  # these labels cannot draw it: not the same pair set
            done = None
        if done is None:
            raise Sc2DataError(_other(out, data, recipe, identity, labels_meta))
    if done is not None:
        return PairsetSummary(out, done["counts"], {s: v["states"] for s, v in
                                                    done["splits"].items()},
                              time.perf_counter() - started, up_to_date=True)
    pairs = drawn if drawn is not None else _draw(recipe, labelled, data, labels_meta)
    names = [s.name for s in recipe.sources]
    folders = [data / n for n in names] or [data]
    datasets = [open_dataset(f) for f in folders]
    ds = datasets[0]
    tmp = out.with_name(f".{out.name}{PARTIAL}")
    shutil.rmtree(tmp, ignore_errors=True)
    (tmp / PACKED_DIR).mkdir(parents=True)
    try:
        parts, states = [], {}
        n_states = len(pairs.group_by([c for c in ("source", "episode", "step")
                                       if c in pairs.column_names]).aggregate([]))
        with progress_bar(n_states, desc="pack", unit="stack", show=progress) as bar:
            for split in SPLITS:
                sub = pairs.filter(pc.equal(pairs["split"], split))
                part, states[split] = _pack_split(datasets, split, sub,
                                                  packed_path(tmp, split), recipe.seed, bar,
                                                  names)
                parts.append(part)
        table = pa.concat_tables(parts)
        pq.write_table(table, tmp / PAIRS_FILE)
        counts: dict[str, dict[str, int]] = {}
        for s, k in zip(table["split"].to_pylist(), table["kind"].to_pylist()):
            counts.setdefault(s, {}).setdefault(k, 0)
            counts[s][k] += 1
        files = content_files(tmp)
        meta = {
            **PAIRSET.header(),
            "recipe_name": recipe.name, "seed": recipe.seed, "recipe": recipe.to_dict(),
            "schema": ds.schema.to_dict(),
            "commands": [{"id": c.id, "text": c.text, "paraphrases": list(c.paraphrases),
                          "train_paraphrases": list(c.train_paraphrases)}
                         for c in recipe.commands],
            "splits": {s: {"pairs": sum(counts.get(s, {}).values()), "states": states[s]}
                       for s in SPLITS},
            "counts": counts,
            "data": {"path": str(data.resolve()), "settings": ds.settings} if not names else
            {"path": str(data.resolve()), "sources": [
                {"name": s.name, "share": s.share, "path": str(f.resolve()),
                 "settings": d.settings, "states": _source_states(pairs, s.name)}
                for s, f, d in zip(recipe.sources, folders, datasets)]},
            "labels": {"fingerprint": identity["labels"], "rules": labels_meta.get("rules")},
            "identity": identity,
            "fingerprint": pairset_fingerprint(tmp),
            "versions": versions(),
        }
        (tmp / META_FILE).write_text(json.dumps(meta, indent=2, default=str))
        for f in [*files, tmp / META_FILE]:
            fsync_path(f)
        if out.exists():
            out.rmdir()  # empty (checked above)
        publish(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        for d in datasets:
            d.close()
    return PairsetSummary(out, counts, states, time.perf_counter() - started)


def _source_states(pairs: pa.Table, name: str) -> dict[str, dict[str, int]]:
    """split → kind → pairs drawn from source ``name``: the mix ``sc2data info`` shows."""
    mine = pairs.filter(pc.equal(pairs["source"], name))
    counts: dict[str, dict[str, int]] = {}
    for s, k in zip(mine["split"].to_pylist(), mine["kind"].to_pylist()):
        counts.setdefault(s, {}).setdefault(k, 0)
        counts[s][k] += 1
    return counts
