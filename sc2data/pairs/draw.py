"""Turn labels into the (command, state, target) pairs the mutual-embedding model trains on.

Kinds of pair (paper §3.3, "Dataset"):

* **matched** — a state a command's rule fires on, with that command; target distance 0.
* **mismatched** — the same state with another command, drawn uniformly among the commands whose
  rules do *not* fire on it (so a mismatch is never secretly true); target 1. With ``mismatch =
  "confusable"`` a share of a listed command's mismatches are drawn among the commands its states
  are mistaken for instead (hard negatives: :func:`confusable_mismatches`).
* **null** — a state no command's rule fires on, with a command drawn uniformly; target 1.

A state is drawn for one command (the scarcest of those its rules satisfy). With ``multi_match =
true`` a state drawn so whose other commands' rules fire too is also paired, matched, with each
of them — "collect minerals" and "build a supply depot" on the step an idle SCV starts a depot
beside it — so the model learns to place such a state within reach of every command it
satisfies; these extra matched pairs (no generator call: everything else is drawn as without
them) come on top of the recipe's counts.

States are assigned to train/val/test either by episode (default: no episode on two sides, so
adjacent, near-identical frames cannot leak across the split) or at random over pairs, as the paper
did. Each command's quota and the null quota are apportioned over the splits by largest remainder,
so the totals are exactly the recipe's. Everything is drawn from one seeded generator.

Command texts: a pair's ``command`` is its command's canonical text, except in the train split of
a recipe whose commands list ``train_paraphrases``: there each pair's text is the canonical one
with probability ½ (:data:`P_CANONICAL`), else one of its command's training phrasings, uniformly.
These draws come from a second stream of the recipe's seed, after everything else, so the
phrasings change no state, split, kind or command id of the pairs — only the train split's text
column — and a recipe without them draws exactly the pairs it always did. Validation and test
pairs keep the canonical text: test accuracy stays the paper's measure, and the held-out
``paraphrases`` are never drawn at all (evaluation re-scores test pairs with them).

Several sources (a recipe's ``[sources]``: say the reduced-random rollout and a trained policy's):
each source's episodes are split on their own (episode-disjoint within every source), and every
quota — each command's and the null one, in every split — is apportioned over the sources by
their shares (largest remainder), so each split holds each source's share of each command. The
pairs gain a ``source`` column (episodes are numbered per source). A recipe of one source draws
exactly what it always drew: the same generator calls in the same order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.recipe import Command, Recipe, apportion
from sc2data.ground.vocab import SPLITS

PAIR_SCHEMA = pa.schema([
    ("split", pa.string()), ("episode", pa.int64()), ("step", pa.int32()),
    ("command_id", pa.string()), ("command", pa.string()), ("target", pa.float32()),
    ("kind", pa.string()), ("label", pa.string()),
])
"""Columns of pairs.parquet before packing adds ``state`` (see docs/pairset.md)."""
SOURCES_SCHEMA = pa.schema([PAIR_SCHEMA.field(0), ("source", pa.string()),
                            *(PAIR_SCHEMA.field(i) for i in range(1, len(PAIR_SCHEMA)))])
"""The same for a recipe of several sources: ``source`` names each state's dataset."""
P_CANONICAL = 0.5
"""Share of training pairs (of a command with training phrasings) that keep the canonical text."""
MARGIN = 1.25
"""More data than the observed yield says a shortage asks for: new episodes yield more or less
than the old, and the episodes are split again."""


class NotEnoughStates(Sc2DataError):
    """The labelled data holds too few positives (or nulls) for the recipe's quotas."""

    def __init__(self, shortfall: str, hint: str, episodes: int | None) -> None:
        super().__init__(f"{shortfall}; {hint}")
        self.shortfall = shortfall
        """What was found against what the recipe asks for."""
        self.episodes = episodes
        """Episodes in all that should meet the quotas (None: more data cannot help)."""


@dataclass(frozen=True)
class Labelled:
    """Every stack of a dataset with which of the recipe's rules fire on it."""

    episode: np.ndarray  # (N,) int64
    step: np.ndarray  # (N,) int32
    fires: np.ndarray  # (N, C) bool, columns in the recipe's command order

    def __post_init__(self) -> None:
        n = len(self.episode)
        if len(self.step) != n or self.fires.shape[0] != n:
            raise ValueError("episode, step and fires must have the same length")


class SourceShortage(NotEnoughStates):
    """Too few states in some sources of a recipe of several: per short source, the episodes
    that should meet its quotas (None: more of its data cannot help)."""

    def __init__(self, shortfall: str, hint: str, sources: dict[str, int | None]) -> None:
        super().__init__(shortfall, hint, None)
        self.sources = sources


def _assign_episodes(episodes: np.ndarray, fractions: Sequence[float],
                     rng: np.random.Generator) -> dict[int, int]:
    """Map each episode to a split index, shuffled, in proportion to the fractions."""
    unique = np.unique(episodes)
    counts = apportion(len(unique), fractions)
    for i, c in enumerate(counts):  # every split gets at least one episode
        if c == 0:
            counts[int(np.argmax(counts))] -= 1
            counts[i] = 1
    shuffled = rng.permutation(unique)
    split_of = np.repeat(np.arange(len(fractions)), counts)
    return {int(e): int(s) for e, s in zip(shuffled, split_of)}


def build_pairs(recipe: Recipe, data: Labelled | Sequence[Labelled]) -> pa.Table:
    """Draw the recipe's pairs from labelled stacks (one :class:`Labelled` per source, in the
    recipe's order); deterministic for ``recipe.seed``."""
    sources = [data] if isinstance(data, Labelled) else list(data)
    shares = recipe.shares
    if len(sources) != len(shares):
        raise ValueError(f"recipe {recipe.name!r} has {len(shares)} source(s), got {len(sources)}")
    s = _Stacks.of(sources, [x.name for x in recipe.sources] or [""])
    rng = np.random.default_rng(np.random.SeedSequence([recipe.seed, 0x5C2DA7A]))
    split_of, quotas, null_quota, pools = _split(recipe, s, rng)
    chosen = _choose(recipe, s, split_of, quotas=quotas, null_quota=null_quota, pools=pools,
                     rng=rng)
    return _pair_table(recipe, s, chosen, rng)


@dataclass(frozen=True)
class _Stacks:
    """Every source's labelled stacks, each sorted by (episode, step), laid end to end."""

    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
    """(episode, step, fires) of each source."""
    names: list[str]
    episode: np.ndarray
    step: np.ndarray
    fires: np.ndarray
    src: np.ndarray
    """The source of each stack (its index in :attr:`parts`)."""

    @classmethod
    def of(cls, sources: Sequence[Labelled], names: list[str]) -> _Stacks:
        parts = []
        for d in sources:
            order = np.lexsort((d.step, d.episode))  # input order must not matter
            parts.append((d.episode[order], d.step[order], d.fires[order]))
        return cls(parts, names, np.concatenate([p[0] for p in parts]),
                   np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]),
                   np.repeat(np.arange(len(parts)), [len(p[0]) for p in parts]))

    @property
    def is_null(self) -> np.ndarray:
        return ~self.fires.any(axis=1)

    def what(self, name: str, k: int) -> str:
        """A quota's name in a shortage message: the command (or null), and its source."""
        return name if len(self.parts) == 1 else f"{name} from {self.names[k]}"


def _split(recipe: Recipe, s: _Stacks, rng: np.random.Generator
           ) -> tuple[np.ndarray, np.ndarray, list[int], list[int]]:
    """Each stack's pool, the states each command needs from each pool, the null states each
    pool needs, and the pools: by episode, the splits (each source's episodes split on their
    own); random, one pool, split into pairs afterwards."""
    fractions, n_cmd = recipe.split.fractions, len(recipe.commands)
    if recipe.split.method != "episode":
        return (np.zeros(len(s.episode), np.int64),
                np.array([[recipe.pairs.states_per_command] * n_cmd]),
                [recipe.pairs.null_states], [0])
    for k, (e, _, f) in enumerate(s.parts):
        n = len(np.unique(e))
        if n < len(fractions):
            error = _too_few_episodes(recipe, f, ~f.any(axis=1), n)
            if len(s.parts) == 1:
                raise error
            raise SourceShortage(f"source {s.names[k]}: {error.shortfall}",
                                 f"grow source {s.names[k]}", {s.names[k]: error.episodes})
    split_of = np.empty(len(s.episode), np.int64)
    for k in range(len(s.parts)):
        mine = s.src == k
        split_map = _assign_episodes(s.episode[mine], fractions, rng)
        split_of[mine] = np.fromiter((split_map[int(e)] for e in s.episode[mine]), np.int64,
                                     int(mine.sum()))
    quotas = np.array([apportion(recipe.pairs.states_per_command, fractions)] * n_cmd).T
    return (split_of, quotas, apportion(recipe.pairs.null_states, fractions),
            list(range(len(SPLITS))))


def _choose(recipe: Recipe, s: _Stacks, split_of: np.ndarray, *, quotas: np.ndarray,
            null_quota: list[int], pools: list[int], rng: np.random.Generator
            ) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(pool, state indices, command indices, -1 for null) of the states drawn for each quota;
    a shortage (one line) if any quota cannot be met. A state that satisfies every command has
    no possible mismatch: it is never drawn."""
    used = s.fires.all(axis=1)
    chosen: list[tuple[int, np.ndarray, np.ndarray]] = []
    filled: dict[str, list[int]] = {}  # what → [states usable, states the recipe asks for]
    unmet: list[tuple[str, int, int]] = []  # (what, found, need) of each quota not met

    def short(what: str, found: int, need: int) -> bool:
        f = filled.setdefault(what, [0, 0])
        f[0] += min(found, need)
        f[1] += need
        if found < need:
            unmet.append((what, found, need))
        return found < need

    is_null = s.is_null
    for pool in pools:
        for k in range(len(s.parts)):
            mine = (split_of == pool) & (s.src == k)
            # Rarest command first, so a stack satisfying two commands serves the scarcer one.
            rarity = np.argsort((s.fires & mine[:, None]).sum(axis=0), kind="stable")
            for c in rarity:
                need = apportion(int(quotas[pool][c]), recipe.shares)[k]
                cand = np.flatnonzero(s.fires[:, c] & mine & ~used)
                if short(s.what(recipe.commands[c].id, k), len(cand), need):
                    continue
                pick = np.sort(rng.choice(cand, size=need, replace=False))
                used[pick] = True
                chosen.append((pool, pick, np.full(need, c)))
            need = apportion(null_quota[pool], recipe.shares)[k]
            cand = np.flatnonzero(is_null & mine)
            if not short(s.what("null", k), len(cand), need):
                chosen.append((pool, np.sort(rng.choice(cand, size=need, replace=False)),
                               np.full(need, -1)))
    if unmet and len(s.parts) == 1:
        n_episodes = len(np.unique(s.episode))
        raise _shortage(recipe, s.fires, is_null, filled, unmet, n_episodes)
    if unmet:
        raise _source_shortage(recipe, s.parts, s.names, filled, unmet)
    return chosen


def _pair_columns(s: _Stacks, chosen: list[tuple[int, np.ndarray, np.ndarray]], ids: np.ndarray,
                  n_cmd: int, rng: np.random.Generator, multi_match: bool = False
                  ) -> dict[str, np.ndarray]:
    """The pairs of the states drawn, column by column: a matched and a mismatched pair per
    command state (``multi_match``: and a matched pair with each other command it satisfies),
    a null pair (a random command) per null state."""
    columns: dict[str, list[np.ndarray]] = {k: [] for k in ("pool", "idx", "cmd", "target",
                                                             "kind", "label")}

    def add(pool: int, idx: np.ndarray, cmd: np.ndarray, target: float, kind: str,
            label: np.ndarray) -> None:
        columns["pool"].append(np.full(len(idx), pool))
        columns["idx"].append(idx)
        columns["cmd"].append(cmd)
        columns["target"].append(np.full(len(idx), target, np.float32))
        columns["kind"].append(np.full(len(idx), kind, object))
        columns["label"].append(label)

    for pool, idx, cmd in chosen:
        if cmd.size and cmd[0] < 0:
            add(pool, idx, rng.integers(0, n_cmd, len(idx)), 1.0, "null", ids[cmd])
            continue
        add(pool, idx, cmd, 0.0, "matched", ids[cmd])
        add(pool, idx, _draw_mismatch(s.fires[idx], rng), 1.0, "mismatched", ids[cmd])
        if multi_match:
            also = s.fires[idx].copy()
            also[np.arange(len(idx)), cmd] = False
            rows, others = np.nonzero(also)
            add(pool, idx[rows], others, 0.0, "matched", ids[cmd[rows]])
    return {k: np.concatenate(v) for k, v in columns.items()}


def _pair_table(recipe: Recipe, s: _Stacks, chosen: list[tuple[int, np.ndarray, np.ndarray]],
                rng: np.random.Generator) -> pa.Table:
    """The pairs as a table in a stable, readable order (split, then source, episode, step),
    training pairs' texts drawn from the training phrasings."""
    commands = recipe.commands
    ids = np.array([c.id for c in commands] + [""], dtype=object)  # ids[-1] = "" for null
    col = _pair_columns(s, chosen, ids, len(commands), rng, recipe.pairs.multi_match)
    if recipe.pairs.mismatch == "confusable":
        col["cmd"] = confusable_mismatches(recipe, s.fires[col["idx"]], col["cmd"],
                                           col["kind"] == "mismatched", col["label"])
    pool, idx, cmd = col["pool"], col["idx"], col["cmd"]
    if recipe.split.method == "random":
        pool = rng.permutation(np.repeat(np.arange(len(SPLITS)),
                                         apportion(len(idx), recipe.split.fractions)))
    texts = np.array([c.text for c in commands], dtype=object)
    several = len(s.parts) > 1
    source = {"source": pa.array(np.array(s.names, dtype=object)[s.src[idx]], pa.string())} \
        if several else {}
    table = pa.table({
        "split": pa.array(np.array(SPLITS, dtype=object)[pool], pa.string()),
        **source,
        "episode": pa.array(s.episode[idx], pa.int64()),
        "step": pa.array(s.step[idx], pa.int32()),
        "command_id": pa.array(ids[cmd], pa.string()),
        "command": pa.array(texts[cmd], pa.string()),
        "target": pa.array(col["target"], pa.float32()),
        "kind": pa.array(col["kind"], pa.string()),
        "label": pa.array(col["label"], pa.string()),
    }, schema=SOURCES_SCHEMA if several else PAIR_SCHEMA)
    keys = np.lexsort((s.step[idx], s.episode[idx], s.src[idx], pool))
    table = table.take(pa.array(keys))
    if any(c.train_paraphrases for c in commands):
        texts = draw_texts(commands, cmd[keys], pool[keys] == SPLITS.index("train"), recipe.seed)
        table = table.set_column(table.schema.get_field_index("command"), "command",
                                 pa.array(texts, pa.string()))
    return table


def draw_texts(commands: Sequence[Command], cmd: np.ndarray, train: np.ndarray, seed: int
               ) -> np.ndarray:
    """Each pair's command text: canonical, or (a training pair, with probability 1 − ½) one of
    its command's training phrasings, uniformly; from the seed's own stream for texts."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5C2DA7A, 1]))
    out = np.array([c.text for c in commands], dtype=object)[cmd]
    u = rng.random(int(train.sum()))  # one draw per training pair, in the table's order
    rows = np.flatnonzero(train)
    for c, command in enumerate(commands):
        k = len(command.train_paraphrases)
        mine = (cmd[rows] == c) & (u >= P_CANONICAL)
        if k == 0 or not mine.any():
            continue
        pick = np.minimum(((u[mine] - P_CANONICAL) / (1 - P_CANONICAL) * k).astype(int), k - 1)
        out[rows[mine]] = np.array(command.train_paraphrases, dtype=object)[pick]
    return out


def _draw_mismatch(fires: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """For each state, a command drawn uniformly among those whose rule does not fire on it."""
    allowed = ~fires
    # Uniform choice among allowed columns: rank random keys, take the best allowed one.
    keys = np.where(allowed, rng.random(allowed.shape), -1.0)
    return keys.argmax(axis=1)


def confusable_mismatches(recipe: Recipe, fires: np.ndarray, cmd: np.ndarray,
                          mismatched: np.ndarray, own: np.ndarray) -> np.ndarray:
    """``mismatch = "confusable"``: each mismatched pair of a state of a listed command names,
    with probability ``confusable_share``, one of the commands it is mistaken for (uniformly
    among those whose rules do not fire on it; none left: the uniform draw stands). Drawn from
    the seed's own stream, after the uniform draws, so nothing else of the pairs changes."""
    ids = [c.id for c in recipe.commands]
    hard = np.zeros((len(ids), len(ids)), bool)
    for key, others in recipe.pairs.confusable.items():
        hard[ids.index(key), [ids.index(o) for o in others]] = True
    rows = np.flatnonzero(mismatched)
    rng = np.random.default_rng(np.random.SeedSequence([recipe.seed, 0x5C2DA7A, 2]))
    u, keys = rng.random(len(rows)), rng.random((len(rows), len(ids)))  # one draw each, in order
    of = np.array([ids.index(i) for i in own[rows]], np.int64)
    allowed = hard[of] & ~fires[rows]
    use = (u < recipe.pairs.confusable_share) & allowed.any(axis=1)
    out = cmd.copy()
    out[rows[use]] = np.where(allowed, keys, -1.0).argmax(axis=1)[use]
    return out


def _available(recipe: Recipe, fires: np.ndarray, is_null: np.ndarray) -> dict[str, int]:
    """States each command (and ``null``) could be drawn from in the whole data."""
    drawable = fires & ~fires.all(axis=1)[:, None]  # no mismatch possible: never drawn
    counts = {c.id: int(drawable[:, j].sum()) for j, c in enumerate(recipe.commands)}
    return {**counts, "null": int(is_null.sum())}


def _episodes(n: int) -> str:
    return f"{n} episode{'' if n == 1 else 's'}"


def _never(what: str) -> str:
    return "no state is null" if what == "null" else f"{what} never fires"


def _too_few_episodes(recipe: Recipe, fires: np.ndarray, is_null: np.ndarray, n_episodes: int
                      ) -> NotEnoughStates:
    """The error of too few episodes for an episode split, asking for the episodes whose yield,
    at this data's rate per episode, meets every quota with :data:`MARGIN` to spare."""
    k = len(recipe.split.fractions)
    shortfall = (f"an episode-disjoint split needs at least {_episodes(k)}; the data has "
                 f"{n_episodes}")
    asks = {c.id: recipe.pairs.states_per_command for c in recipe.commands}
    asks["null"] = recipe.pairs.null_states
    have = _available(recipe, fires, is_null)
    never = [w for w, n in asks.items() if n and have[w] == 0]
    if never:
        return NotEnoughStates(shortfall, f"{', '.join(map(_never, never))} in the data; check "
                               f"the agent and the rule", None)
    ratio = max([n / have[w] for w, n in asks.items() if n] or [0.0])
    want = max(k, int(np.ceil(n_episodes * ratio * MARGIN)))
    return NotEnoughStates(shortfall, f"roll out {want} episodes in all", want)


def _source_shortage(recipe: Recipe, parts: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
                     names: Sequence[str], filled: dict[str, list[int]],
                     unmet: list[tuple[str, int, int]]) -> SourceShortage:
    """Unmet quotas of a recipe of several sources: each short one, then per short source the
    episodes that should meet its quotas, as :func:`_shortage` reckons them on its data."""
    parts_short, need = [], {}
    for k, name in enumerate(names):
        suffix = f" from {name}"
        mine = {w[:-len(suffix)]: f for w, f in filled.items() if w.endswith(suffix)}
        short = [(w[:-len(suffix)], f, n) for w, f, n in unmet if w.endswith(suffix)]
        if not short:
            continue
        episode, _, fires = parts[k]
        e = _shortage(recipe, fires, ~fires.any(axis=1), mine, short, len(np.unique(episode)))
        parts_short.append(f"{name}: " + e.shortfall.split(": ", 1)[1])
        need[name] = e.episodes
    shortfall = f"too few labelled states for the recipe's sources: {'; '.join(parts_short)}"
    hint = ", ".join(f"grow {n} to {e} episodes" if e else f"{n} can never fill it (check its "
                     f"agent and the rules)" for n, e in need.items())
    return SourceShortage(shortfall, hint, need)


def _shortage(recipe: Recipe, fires: np.ndarray, is_null: np.ndarray,
              filled: dict[str, list[int]], unmet: list[tuple[str, int, int]], n_episodes: int
              ) -> NotEnoughStates:
    """The one-line error of unmet quotas: each short one's usable states against the recipe's
    total, and how many episodes in all should meet them: the data scaled by the worst ratio of
    need to found of any unmet quota (of the whole data's, where a split found none), with
    :data:`MARGIN`."""
    order = [*(c.id for c in recipe.commands), "null"]  # the recipe's order
    parts = ", ".join(f"{w} {filled[w][0]} of {filled[w][1]} the recipe asks for" for w in order
                      if w in filled and filled[w][0] < filled[w][1])
    shortfall = f"too few labelled states for the recipe: {parts} (in {_episodes(n_episodes)})"
    have = _available(recipe, fires, is_null)
    never = [w for w, (f, n) in filled.items() if f < n and have[w] == 0]
    if never:
        return NotEnoughStates(shortfall, f"{', '.join(map(_never, never))} in the data; check "
                               f"the agent and the rule", None)
    ratio = max(need / found if found else filled[w][1] / have[w] for w, found, need in unmet)
    episodes = max(n_episodes + 1, int(np.ceil(n_episodes * ratio * MARGIN)))
    return NotEnoughStates(shortfall, f"roll out {episodes} episodes in all", episodes)
