"""Recipes: the one reproducible description of a dataset, from rollout settings to final pairs.

A recipe is a TOML file in ``manifests/``. It is parsed strictly: an unknown key, a value of the
wrong type or an impossible count is an error that names the field. Example (the paper's dataset)::

    name = "buildmarines-paper"
    seed = 0

    [rollout]              # what `sc2data rollout` runs
    env = "sim"
    agent = "reduced-random"
    episodes = 600
    layers = "paper"

    [commands.build_supply_depot]      # one table per command; the id is the rule id
    text = "build a supply depot"      # canonical: the rule's own command text
    train_paraphrases = ["build supply", "make a depot"]  # trained on (see sc2data.pairs.draw)
    paraphrases = ["construct a depot"]                   # held out: evaluation only

    [pairs]
    states_per_command = 10000         # matched pairs per command (and as many mismatched)
    null_states = 50000                # states no rule fires on, each paired as a mismatch
    mismatch = "uniform"               # mismatched command: uniform over those not satisfied

    # multi_match = true: a state drawn for one command whose other rules fire too is also
    # paired, matched, with each of those commands (extra matched pairs; see sc2data.pairs.draw)
    # mismatch = "confusable": a share of each listed command's mismatched pairs name one of the
    # commands its states are mistaken for (hard negatives; `sc2data rl agreement` shows them)
    # confusable_share = 0.5
    # [pairs.confusable]
    # build_supply_depot = ["build_barracks"]

    [split]
    method = "episode"                 # episode-disjoint; "random" reproduces the paper
    train = 0.6667
    val = 0.1667
    test = 0.1666

A recipe may draw from several datasets: ``[sources.NAME]`` tables (two or more), each a
``share`` of every command's states and of the null states in every split, plus any
``[rollout]`` key in which its data differs (``agent = "policy:runs/rl"``, ``episodes``)::

    [sources.random]
    share = 0.5
    [sources.policy]
    share = 0.5
    agent = "policy:runs/rl-narr"
    episodes = 10

``sc2data pair RECIPE --data DIR`` then reads source NAME from ``DIR/NAME`` (see
:mod:`sc2data.pairs.draw`). Without ``[sources]``, the recipe's one source is its
``[rollout]``, and its pairs are what they always were.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.vocab import (
    BACKENDS,
    LAYER_SETS,
    MISMATCH_METHODS,
    SPLIT_METHODS,
    SPLITS,
    STEP_MUL,
)


class RecipeError(Sc2DataError):
    """A malformed recipe; the message names the file and the field."""


@dataclass(frozen=True)
class RolloutSpec:
    """A recipe's ``[rollout]`` section: which backend and agent play how many episodes.

    :class:`sc2data.data.rollout.RolloutConfig` extends it with what only a run decides (seed,
    shard size, codec), so the defaults below are the only ones.
    """

    env: str = "sim"
    """Backend: ``sim`` (embedded simulator) or ``sc2`` (the real game through pysc2)."""
    agent: str = "reduced-random"
    """Agent name for ``sc2data.game.agents.make_agent``."""
    episodes: int = 1
    """Episodes to play."""
    layers: str = "paper"
    """Layer set: ``paper`` (13 screen + 7 minimap) or ``full`` (27 + 11)."""
    step_mul: int = STEP_MUL
    """Game loops per agent step."""


@dataclass(frozen=True)
class Source:
    """One dataset a recipe draws from: its rollout settings and its share of the states."""

    name: str
    """Names the dataset folder: ``pair --data DIR`` reads it from ``DIR/NAME``."""
    share: float
    """Share of every command's states (and of the null states) in every split taken from it."""
    rollout: RolloutSpec


@dataclass(frozen=True)
class Command:
    """A command: the rule that labels it, its canonical text, its held-out paraphrases (never
    trained on) and its training phrasings (drawn for training pairs beside the canonical text)."""

    id: str
    text: str
    paraphrases: tuple[str, ...] = ()
    train_paraphrases: tuple[str, ...] = ()


def phrase_key(text: str) -> str:
    """What makes two phrases the same: their lower-cased words and numbers, in order. Both text
    encoders ignore case, and the word-vector one punctuation, so "Make a depot!" is "make a
    depot" — a held-out paraphrase that differs from a training phrase only so is no test."""
    return " ".join(re.findall(r"[a-z0-9]+", text.lower()))


@dataclass(frozen=True)
class PairSpec:
    """How many pairs of each kind, and how mismatches are drawn."""

    states_per_command: int
    null_states: int
    mismatch: str = "uniform"
    confusable: dict[str, tuple[str, ...]] = field(default_factory=dict)
    """``mismatch = "confusable"``: per command id, the commands its states are mistaken for."""
    confusable_share: float = 0.5
    """The share of such a command's mismatched pairs drawn among its confusable commands."""
    multi_match: bool = False
    """A drawn state that satisfies other commands too is also matched with each of them."""


@dataclass(frozen=True)
class SplitSpec:
    """Train/val/test fractions and how states are assigned to them."""

    method: str = "episode"
    fractions: tuple[float, float, float] = (2 / 3, 1 / 6, 1 / 6)


@dataclass(frozen=True)
class Recipe:
    """A parsed, validated recipe."""

    name: str
    seed: int
    rollout: RolloutSpec
    commands: tuple[Command, ...]
    pairs: PairSpec
    split: SplitSpec = field(default_factory=SplitSpec)
    description: str = ""
    source: str = ""
    """Path the recipe was read from (not part of its identity)."""
    sources: tuple[Source, ...] = ()
    """The datasets it draws from, two or more; none: its one dataset is ``rollout``'s."""

    @property
    def rule_ids(self) -> tuple[str, ...]:
        return tuple(c.id for c in self.commands)

    @property
    def shares(self) -> tuple[float, ...]:
        """Each source's share, in order (``(1.0,)`` for a recipe of one source)."""
        return tuple(s.share for s in self.sources) or (1.0,)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form recorded in every pair set (``source`` left out)."""
        d = asdict(self)
        d.pop("source")
        for c in d["commands"]:  # absent when empty: older recipes keep their identity
            if not c["train_paraphrases"]:
                del c["train_paraphrases"]
        if not self.sources:  # likewise
            del d["sources"]
        if self.pairs.mismatch != "confusable":  # likewise
            del d["pairs"]["confusable"], d["pairs"]["confusable_share"]
        else:
            d["pairs"]["confusable"] = {k: list(v) for k, v in self.pairs.confusable.items()}
        if not self.pairs.multi_match:  # likewise
            del d["pairs"]["multi_match"]
        return d


def _check_keys(where: str, table: Mapping[str, Any],
                allowed: Mapping[str, type | tuple[type, ...]],
                required: tuple[str, ...] = ()) -> None:
    for key, value in table.items():
        if key not in allowed:
            raise RecipeError(f"{where}: unknown key {key!r} (allowed: {', '.join(allowed)})")
        want = allowed[key]
        # bool is an int in Python; a count given as true/false is still a type error.
        if not isinstance(value, want) or (isinstance(value, bool) and bool not in
                                           (want if isinstance(want, tuple) else (want,))):
            names = " or ".join(t.__name__ for t in (want if isinstance(want, tuple) else (want,)))
            raise RecipeError(f"{where}.{key} must be {names}, got {type(value).__name__} "
                              f"{value!r}")
    for key in required:
        if key not in table:
            raise RecipeError(f"{where}: missing required key {key!r}")


def _choice(where: str, value: str, choices: tuple[str, ...]) -> str:
    if value not in choices:
        raise RecipeError(f"{where} must be one of {', '.join(choices)}; got {value!r}")
    return value


def _positive(where: str, value: int, allow_zero: bool = False) -> int:
    if value < 0 or (value == 0 and not allow_zero):
        raise RecipeError(f"{where} must be a {'non-negative' if allow_zero else 'positive'} "
                          f"integer; got {value}")
    return value


NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
"""A recipe name: it names folders (``runs/{name}__…``, ``DATA/pairs-{name}``), so it stays one
plain path component."""
MAX_EPISODES = 1_000_000
"""Far beyond any dataset here (the paper's needs 2,400); a typo of a few zeros is an error, not
a rollout that runs for years."""
MAX_STATES = 10_000_000
MAX_TEXT = 200
"""Characters of a command text or paraphrase: a command, not a document."""


def _text(where: str, text: str) -> str:
    if not text.strip():
        raise RecipeError(f"{where} must not be empty")
    if len(text) > MAX_TEXT:
        raise RecipeError(f"{where} is {len(text):,} characters long; a command text has at "
                          f"most {MAX_TEXT}")
    return text


def parse(data: Mapping[str, Any], source: str = "<recipe>") -> Recipe:
    """Validate a recipe's TOML tables and build a :class:`Recipe`."""
    w = source
    _check_keys(w, data, {"name": str, "seed": int, "description": str, "rollout": dict,
                          "commands": dict, "pairs": dict, "split": dict, "sources": dict},
                required=("name", "seed", "rollout", "commands", "pairs"))
    if not NAME.fullmatch(data["name"]) or ".." in data["name"]:
        raise RecipeError(f"{w}: name {data['name'][:80]!r} must be 1–64 letters, digits, '.', "
                          f"'_' or '-' (it names folders), starting with a letter or digit")
    if not 0 <= data["seed"] < 2**63:
        raise RecipeError(f"{w}: seed must be a non-negative 64-bit integer; got {data['seed']}")

    r = data["rollout"]
    rollout = _rollout(f"{w} [rollout]", r)
    sources = _sources(w, data.get("sources", {}), r)

    if not data["commands"]:
        raise RecipeError(f"{w} [commands]: at least one command is needed")
    commands = []
    for cid, c in data["commands"].items():
        where = f"{w} [commands.{cid}]"
        if not isinstance(c, dict):
            raise RecipeError(f"{where} must be a table with text = \"...\"")
        _check_keys(where, c, {"text": str, "paraphrases": list, "train_paraphrases": list},
                    required=("text",))
        _text(f"{where}.text", c["text"])
        lists = {k: c.get(k, []) for k in ("train_paraphrases", "paraphrases")}
        for key, phrases in lists.items():
            for p in phrases:
                if not isinstance(p, str) or not phrase_key(p):
                    raise RecipeError(f"{where}.{key} must be a list of phrases with at least "
                                      f"one word each; got {p!r}")
                _text(f"{where}.{key}", p)
        commands.append(Command(cid, c["text"], tuple(lists["paraphrases"]),
                                tuple(lists["train_paraphrases"])))
    _check_phrases(w, commands)

    p = dict(data["pairs"])
    _check_keys(f"{w} [pairs]", p, {"states_per_command": int, "null_states": int,
                                    "mismatch": str, "confusable": dict,
                                    "confusable_share": (int, float), "multi_match": bool},
                required=("states_per_command", "null_states"))
    p["confusable"] = _confusable(w, p, commands)
    if "confusable_share" in p:
        p["confusable_share"] = float(p["confusable_share"])
    pairs = PairSpec(**p)
    _positive(f"{w} [pairs].states_per_command", pairs.states_per_command)
    _positive(f"{w} [pairs].null_states", pairs.null_states, allow_zero=True)
    for field_name in ("states_per_command", "null_states"):
        if getattr(pairs, field_name) > MAX_STATES:
            raise RecipeError(f"{w} [pairs].{field_name} must be at most {MAX_STATES:,}")
    _choice(f"{w} [pairs].mismatch", pairs.mismatch, MISMATCH_METHODS)
    if len(commands) < 2:
        raise RecipeError(f"{w} [commands]: mismatched pairs need at least two commands")

    s = dict(data.get("split", {}))
    _check_keys(f"{w} [split]", s, {"method": str, "train": (int, float), "val": (int, float),
                                    "test": (int, float)})
    method = _choice(f"{w} [split].method", s.pop("method", "episode"), SPLIT_METHODS)
    fractions = tuple(float(s.get(k, d)) for k, d in zip(SPLITS, SplitSpec().fractions))
    if not all(f > 0 and math.isfinite(f) for f in fractions) or abs(sum(fractions) - 1.0) > 1e-3:
        raise RecipeError(f"{w} [split]: train, val and test must be positive and sum to 1; "
                          f"got {', '.join(f'{f:g}' for f in fractions)}")
    total = sum(fractions)
    split = SplitSpec(method, tuple(f / total for f in fractions))  # type: ignore[arg-type]
    for name, n in zip(SPLITS, pairs_per_split(pairs, len(commands), split), strict=True):
        if n == 0:
            raise RecipeError(f"{w} [pairs]: these counts leave the {name} split without pairs; "
                              f"raise states_per_command or null_states")

    return Recipe(name=data["name"], seed=data["seed"], rollout=rollout, commands=tuple(commands),
                  pairs=pairs, split=split, description=data.get("description", ""),
                  source=source, sources=sources)


def _confusable(w: str, p: Mapping[str, Any], commands: Sequence[Command]
                ) -> dict[str, tuple[str, ...]]:
    """``[pairs.confusable]`` checked: only with ``mismatch = "confusable"`` (which needs it),
    every key and listed id a command of the recipe and not the key itself; the share in
    (0, 1]."""
    table, method = p.get("confusable", {}), p.get("mismatch", "uniform")
    where = f"{w} [pairs.confusable]"
    if method != "confusable":
        if table or "confusable_share" in p:
            raise RecipeError(f"{where} and confusable_share apply only with mismatch = "
                              f"\"confusable\"; set it, or drop them")
        return {}
    if not table:
        raise RecipeError(f"{w} [pairs]: mismatch = \"confusable\" needs a [pairs.confusable] "
                          f"table (command id = [ids it is mistaken for])")
    ids = [c.id for c in commands]
    out: dict[str, tuple[str, ...]] = {}
    for key, others in table.items():
        if key not in ids:
            raise RecipeError(f"{where}: {key!r} is not a command of this recipe (its commands: "
                              f"{', '.join(ids)})")
        if not (isinstance(others, list) and others and all(o in ids and o != key
                                                            for o in others)):
            raise RecipeError(f"{where}.{key} must be a non-empty list of the recipe's other "
                              f"command ids ({', '.join(i for i in ids if i != key)}); got "
                              f"{others!r}")
        out[key] = tuple(others)
    share = p.get("confusable_share", 0.5)
    if isinstance(share, bool) or not (math.isfinite(share) and 0 < share <= 1):
        raise RecipeError(f"{w} [pairs].confusable_share must be a number in (0, 1]; got "
                          f"{share!r}")
    return out


_ROLLOUT_KEYS: dict[str, type] = {"env": str, "agent": str, "episodes": int, "layers": str,
                                  "step_mul": int}


def _rollout(where: str, r: Mapping[str, Any]) -> RolloutSpec:
    _check_keys(where, r, _ROLLOUT_KEYS)
    rollout = RolloutSpec(**r)
    _choice(f"{where}.env", rollout.env, BACKENDS)
    _choice(f"{where}.layers", rollout.layers, LAYER_SETS)
    _positive(f"{where}.episodes", rollout.episodes)
    if rollout.episodes > MAX_EPISODES:
        raise RecipeError(f"{where}.episodes must be at most {MAX_EPISODES:,}; got "
                          f"{rollout.episodes:,}")
    _positive(f"{where}.step_mul", rollout.step_mul)
    return rollout


def _sources(w: str, table: Mapping[str, Any], defaults: Mapping[str, Any]
             ) -> tuple[Source, ...]:
    """``[sources.NAME]``: two or more, each a share and the ``[rollout]`` keys it changes;
    shares positive and summing to 1; one layer set for all (pairs pack their stacks
    together)."""
    if not table:
        return ()
    if len(table) < 2:
        raise RecipeError(f"{w} [sources]: one source needs no [sources] table; give its "
                          f"settings in [rollout]")
    sources = []
    for name, t in table.items():
        where = f"{w} [sources.{name}]"
        if not isinstance(t, dict):
            raise RecipeError(f"{where} must be a table with share = ...")
        if not NAME.fullmatch(name) or ".." in name:
            raise RecipeError(f"{where}: the name must be 1–64 letters, digits, '.', '_' or '-' "
                              f"(it names the source's folder)")
        _check_keys(where, t, {"share": (int, float), **_ROLLOUT_KEYS}, required=("share",))
        share = float(t["share"])
        if not (share > 0 and math.isfinite(share)):
            raise RecipeError(f"{where}.share must be positive; got {t['share']}")
        spec = _rollout(where, {**defaults, **{k: v for k, v in t.items() if k != "share"}})
        sources.append(Source(name, share, spec))
    total = sum(s.share for s in sources)
    if abs(total - 1.0) > 1e-3:
        raise RecipeError(f"{w} [sources]: the shares must sum to 1; got "
                          f"{', '.join(f'{s.name} {s.share:g}' for s in sources)}")
    layers = {s.rollout.layers for s in sources}
    if len(layers) > 1:
        raise RecipeError(f"{w} [sources]: every source needs the same layers (their stacks "
                          f"are packed together); got {', '.join(sorted(layers))}")
    return tuple(Source(s.name, s.share / total, s.rollout) for s in sources)


def _check_phrases(where: str, commands: Sequence[Command]) -> None:
    """Every phrase (canonical, training, held-out) belongs to one command and one role: a
    held-out paraphrase that is also trained on would measure nothing, and a phrase given to two
    commands would teach the model a contradiction. Phrases compare by :func:`phrase_key`."""
    seen: dict[str, tuple[str, str, str]] = {}  # key → (command id, list name, phrase)
    for c in commands:
        named = [(c.text, "text"), *((p, "train_paraphrases") for p in c.train_paraphrases),
                 *((p, "paraphrases") for p in c.paraphrases)]
        for phrase, role in named:
            key = phrase_key(phrase)
            if key in seen:
                cid, other, first = seen[key]
                same = f"{other} {first!r}" + ("" if cid == c.id else f" of {cid}")
                raise RecipeError(f"{where} [commands.{c.id}].{role}: {phrase!r} is already "
                                  f"{same}; a phrase can be in only one list of one command")
            seen[key] = (c.id, role, phrase)


def apportion(total: int, fractions: Sequence[float]) -> list[int]:
    """Split ``total`` into integers proportional to ``fractions`` (largest remainder)."""
    raw = [f * total for f in fractions]
    counts = [math.floor(r) for r in raw]
    order = sorted(range(len(raw)), key=lambda i: -(raw[i] - counts[i]))  # stable
    for i in order[: total - sum(counts)]:
        counts[i] += 1
    return counts


def pairs_per_split(pairs: PairSpec, n_commands: int, split: SplitSpec) -> list[int]:
    """How many pairs each split gets: a matched and a mismatched pair per command state, and
    the null pairs; per split for an episode split, apportioned afterwards for a random one."""
    if split.method == "random":
        return apportion(2 * n_commands * pairs.states_per_command + pairs.null_states,
                         split.fractions)
    per_command = apportion(pairs.states_per_command, split.fractions)
    null = apportion(pairs.null_states, split.fractions)
    return [2 * n_commands * c + z for c, z in zip(per_command, null, strict=True)]


def load(path: str | Path) -> Recipe:
    """Read and validate a recipe file."""
    path = Path(path)
    try:
        text = path.read_text()
    except IsADirectoryError:
        raise RecipeError(f"recipe {path} is a folder; pass a .toml file") from None
    except OSError as e:
        raise RecipeError(f"cannot read recipe {path}: {e.strerror}") from None
    except UnicodeDecodeError:
        raise RecipeError(f"recipe {path} is not a text file (not UTF-8); pass a .toml recipe") \
            from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise RecipeError(f"{path} is not valid TOML: {e}") from None
    return parse(data, str(path))
