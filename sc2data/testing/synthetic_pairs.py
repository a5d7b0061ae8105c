"""A small synthetic pair set in the exact pair-set folder format, for tests and benchmarks.

It stands in for ``sc2data pair`` output where no rollout exists (tests, the trainer benchmark):
two-frame stacks drawn with BuildMarines' geometry and pysc2's own unit ids, where each
labelled stack carries the one event its command names between frame 0 and frame 1 — a depot or a
barracks blob appears, an SCV appears by the Command Center, a marine by a barracks, minerals rise
by 5 — and null stacks carry only the background motion every stack has (SCVs wander, the selection
changes). Pairs follow the pair-set contract (docs/pairset.md): per labelled state one
matched and one mismatched pair, per null state one null pair; splits are episode-disjoint.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from sc2data._pysc2 import features, units
from sc2data.ground.formats import PAIRSET
from sc2data.ground.recipe import Command
from sc2data.pairs.layout import pairset_fingerprint
from sc2data.pairs.packed import PackedWriter
from sc2data.schema import Schema, StackBatch

COMMANDS: tuple[dict[str, object], ...] = (
    {"id": "build_scv", "text": "build an scv",
     "paraphrases": ["train a worker", "make another scv"]},
    {"id": "collect_minerals", "text": "collect minerals",
     "paraphrases": ["gather minerals", "harvest minerals"]},
    {"id": "build_supply_depot", "text": "build a supply depot",
     "paraphrases": ["construct a supply depot", "make a depot"]},
    {"id": "build_barracks", "text": "build a barracks",
     "paraphrases": ["construct a barracks", "make a barracks"]},
    {"id": "train_marine", "text": "train a marine",
     "paraphrases": ["recruit a marine", "produce a marine"]},
)

_T = units.Terran
_HP = {_T.SCV: 45, _T.Marine: 45, _T.CommandCenter: 1500, _T.SupplyDepot: 400,
       _T.Barracks: 1000, units.Neutral.MineralField: 0}
_K = 64 / 24  # screen pixels per world unit (24 world units across)


@dataclass
class _Frame:
    """One frame's arrays, by schema key, for all 38 pysc2 layers we might keep."""

    screen: dict[str, np.ndarray]
    minimap: dict[str, np.ndarray]
    player: np.ndarray
    score: np.ndarray


def _empty(size: int) -> dict[str, np.ndarray]:
    return {n: np.zeros((size, size), np.int32) for n in
            ("height_map", "visibility_map", "player_id", "player_relative", "unit_type",
             "selected", "unit_hit_points", "unit_density", "unit_density_aa", "camera")}


def _stamp(f: _Frame, unit: int, y: int, x: int, size: int) -> None:
    """Draw a unit as a filled square at screen pixel (y, x), and its dot on the minimap."""
    neutral = unit == units.Neutral.MineralField
    for plane, (py, px, s) in (("screen", (y, x, size)),
                               ("minimap", (int(27 + y / _K), int(20.94 + x / _K),
                                            max(1, round(size / _K))))):
        a = getattr(f, plane)
        sl = (slice(max(py, 0), py + s), slice(max(px, 0), px + s))
        a["unit_type"][sl] = unit
        a["player_relative"][sl] = 3 if neutral else 1
        a["player_id"][sl] = 16 if neutral else 1
        if plane == "screen":
            a["unit_hit_points"][sl] = _HP[unit]
            a["unit_density"][sl] += 1
            a["unit_density_aa"][sl] += 1


def _free_spot(rng: np.random.Generator, occupied: np.ndarray, size: int) -> tuple[int, int]:
    for _ in range(200):
        y, x = int(rng.integers(2, 46 - size)), int(rng.integers(28, 62 - size))
        if not occupied[y:y + size, x:x + size].any():
            return y, x
    return int(rng.integers(2, 46 - size)), int(rng.integers(28, 62 - size))


def _stack(rng: np.random.Generator, event: str | None) -> tuple[_Frame, _Frame]:
    """Two frames: a random base, then the same base with background motion and ``event``."""
    n_scv = int(rng.integers(12, 24))
    buildings = [(_T.SupplyDepot, 5)] * int(rng.integers(0, 4)) + \
        [(_T.Barracks, 8)] * int(rng.integers(0 if event != "train_marine" else 1, 3))
    if event == "build_barracks" and not any(u == _T.SupplyDepot for u, _ in buildings):
        buildings.insert(0, (_T.SupplyDepot, 5))
    occupied = np.zeros((64, 64), bool)
    occupied[17:32, 16:31] = True  # the Command Center
    placed = []
    for unit, size in buildings:
        y, x = _free_spot(rng, occupied, size)
        occupied[y:y + size, x:x + size] = True
        placed.append((unit, y, x, size))
    scvs = np.stack([rng.integers(4, 44, n_scv), rng.integers(4, 24, n_scv)], 1)
    barracks = [(y, x) for u, y, x, _ in placed if u == _T.Barracks]
    marines = [(y + int(rng.integers(8, 11)), x + int(rng.integers(0, 7)))
               for y, x in barracks for _ in range(int(rng.integers(0, 5)))]
    minerals = int(rng.integers(150, 600))
    food_cap = 15 + 8 * sum(u == _T.SupplyDepot for u, *_ in placed)
    army = len(marines)
    player = np.array([1, minerals, 0, n_scv + army, food_cap, army, n_scv, int(rng.integers(0, 3)),
                       army, 0, 0], np.int32)
    collected = int(rng.integers(100, 5000))
    score = np.zeros(len(features.ScoreCumulative), np.int32)
    score[features.ScoreCumulative.score] = army
    score[features.ScoreCumulative.collected_minerals] = collected
    score[features.ScoreCumulative.spent_minerals] = max(0, collected + 50 - minerals)
    score[features.ScoreCumulative.total_value_structures] = 400 + sum(
        100 if u == _T.SupplyDepot else 150 for u, *_ in placed)

    frames = []
    for _ in (0, 1):
        f = _Frame(_empty(64), _empty(64), player.copy(), score.copy())
        for plane in ("screen", "minimap"):
            a = getattr(f, plane)
            rows = slice(0, 48) if plane == "screen" else slice(27, 45)
            cols = slice(0, 64) if plane == "screen" else slice(20, 46)
            a["height_map"][rows, cols] = 160
            a["visibility_map"][rows, cols] = 2
        f.minimap["camera"][27:51, 21:45] = 1
        for mx, my in ((5, 10), (8, 14), (5, 19), (8, 24), (5, 29), (8, 34), (5, 39), (8, 44)):
            _stamp(f, units.Neutral.MineralField, my, mx, 6)
        _stamp(f, _T.CommandCenter, 17, 16, 15)
        for unit, y, x, size in placed:
            _stamp(f, unit, y, x, size)
        for y, x in marines:
            _stamp(f, _T.Marine, y, x, 2)
        for y, x in scvs:
            _stamp(f, _T.SCV, int(y), int(x), 2)
        sel = rng.integers(0, len(scvs))
        f.screen["selected"][scvs[sel][0]:scvs[sel][0] + 2, scvs[sel][1]:scvs[sel][1] + 2] = 1
        frames.append(f)
        scvs = np.clip(scvs + rng.integers(-3, 4, scvs.shape), 2, 45)  # workers move

    f1 = frames[1]
    P, S = features.Player, features.ScoreCumulative
    if event in ("build_supply_depot", "build_barracks"):
        unit, size, cost = ((_T.SupplyDepot, 5, 100) if event == "build_supply_depot"
                            else (_T.Barracks, 8, 150))
        y, x = _free_spot(rng, occupied, size)
        _stamp(f1, unit, y, x, size)
        f1.player[P.minerals] = max(0, minerals - cost)
        f1.score[S.spent_minerals] += cost
    elif event == "build_scv":
        _stamp(f1, _T.SCV, int(rng.integers(32, 36)), int(rng.integers(18, 28)), 2)
        f1.player[[P.food_used, P.food_workers]] += 1
    elif event == "train_marine":
        y, x = barracks[int(rng.integers(len(barracks)))]
        _stamp(f1, _T.Marine, y + 9, x + int(rng.integers(0, 7)), 2)
        f1.player[[P.food_used, P.food_army, P.army_count]] += 1
        f1.score[S.score] += 1
    elif event == "collect_minerals":
        f1.player[P.minerals] += 5
        f1.score[S.collected_minerals] += 5
    return frames[0], frames[1]


def stacks(schema: Schema, events: list[str | None], seed: int) -> StackBatch:
    """A batch of synthetic stacks in ``schema``'s layout, one per event (None = null)."""
    rng = np.random.default_rng(seed)
    out: dict[str, list[np.ndarray]] = {k: [] for k in schema.keys()}
    for event in events:
        pair = _stack(rng, event)
        for l in schema.layers:
            planes = [getattr(f, l.group).get(l.name) for f in pair]
            out[l.key].append(np.stack([p if p is not None else np.zeros((64, 64), np.int32)
                                        for p in planes]).astype(l.dtype))
        for v in schema.vectors:
            vecs = [f.player if v.name == "player" else f.score if v.name == "score_cumulative"
                    else np.zeros(v.size, np.int32) for f in pair]
            out[v.name].append(np.stack(vecs).astype(v.dtype))
    return StackBatch({k: np.stack(a) for k, a in out.items()}, schema)


def write_pairset(out: str | Path, states_per_command: int = 40, null_states: int = 100,
                  episodes: int = 20, seed: int = 0, schema: Schema | None = None,
                  commands: tuple[dict[str, object], ...] = COMMANDS,
                  confusable: dict[str, list[str]] | None = None) -> Path:
    """Write a synthetic pair-set folder (pairs.parquet, pairset.json, packed/*.h5) to ``out``.

    A command listing ``train_paraphrases`` gets them drawn into its train-split pairs' texts,
    as :func:`sc2data.pairs.draw.draw_texts` draws them for a recipe. ``confusable`` (command id
    → commands) names the mismatches of a listed command's states, recorded as a recipe's
    ``mismatch = "confusable"`` table (every such mismatch, not a share)."""
    out = Path(out)
    (out / "packed").mkdir(parents=True, exist_ok=True)
    schema = schema or Schema.paper()
    rng = np.random.default_rng(seed)
    ids = [str(c["id"]) for c in commands]
    labels: list[str | None] = [c for c in ids for _ in range(states_per_command)]
    labels += [None] * null_states
    labels = [labels[i] for i in rng.permutation(len(labels))]
    episode = rng.integers(0, episodes, len(labels))
    order = rng.permutation(episodes)
    n_train, n_val = round(episodes * 2 / 3), round(episodes / 6)
    split_of_episode = {int(e): ("train" if i < n_train else "val" if i < n_train + n_val
                                 else "test") for i, e in enumerate(order)}
    text = {str(c["id"]): str(c["text"]) for c in commands}
    rows: dict[str, list] = {k: [] for k in ("split", "state", "episode", "step", "command_id",
                                             "command", "target", "kind", "label")}
    counts: dict[str, dict[str, int]] = {}
    for split_i, split in enumerate(("train", "val", "test")):
        members = [i for i in range(len(labels)) if split_of_episode[int(episode[i])] == split]
        batch = stacks(schema, [labels[i] for i in members], seed * 1000 + split_i)
        w = PackedWriter(out / "packed" / f"{split}.h5", schema, len(members))
        w.write(batch)
        w.close()
        n_pairs = 0
        for row, i in enumerate(members):
            label = labels[i]
            other = (ids[(ids.index(label) + int(rng.integers(1, len(ids)))) % len(ids)]
                     if label is not None else None)
            if confusable and label in confusable:
                other = confusable[label][row % len(confusable[label])]
            pairs = ([(label, 0.0, "matched"), (other, 1.0, "mismatched")] if label is not None
                     else [(ids[int(rng.integers(len(ids)))], 1.0, "null")])
            for cid, target, kind in pairs:
                for k, v in zip(rows, (split, row, int(episode[i]), i, cid, text[cid], target,
                                       kind, label or "")):
                    rows[k].append(v)
                n_pairs += 1
        counts[split] = {"pairs": n_pairs, "states": len(members)}
    if any(c.get("train_paraphrases") for c in commands):  # drawn as sc2data pair draws them
        from sc2data.pairs.draw import draw_texts

        cmds = [Command(str(c["id"]), str(c["text"]),
                        train_paraphrases=tuple(c.get("train_paraphrases", ())))  # type: ignore
                for c in commands]
        rows["command"] = list(draw_texts(cmds, np.array([ids.index(c) for c in
                                                          rows["command_id"]]),
                                          np.array(rows["split"]) == "train", seed))
    table = pa.table({
        "split": pa.array(rows["split"], pa.string()), "state": pa.array(rows["state"], pa.int64()),
        "episode": pa.array(rows["episode"], pa.int64()),
        "step": pa.array(rows["step"], pa.int32()),
        "command_id": pa.array(rows["command_id"], pa.string()),
        "command": pa.array(rows["command"], pa.string()),
        "target": pa.array(rows["target"], pa.float32()),
        "kind": pa.array(rows["kind"], pa.string()), "label": pa.array(rows["label"], pa.string()),
    })
    pq.write_table(table, out / "pairs.parquet")
    meta = {
        **PAIRSET.header(),
        "recipe": {"name": "synthetic", "states_per_command": states_per_command,
                   "null_states": null_states, "episodes": episodes,
                   **({"pairs": {"mismatch": "confusable", "confusable": confusable}}
                      if confusable else {})},
        "recipe_name": "synthetic", "seed": seed, "schema": schema.to_dict(),
        "commands": [dict(c) for c in commands], "splits": counts,
        "fingerprint": pairset_fingerprint(out), "versions": {},
    }
    (out / "pairset.json").write_text(json.dumps(meta, indent=2))
    return out
