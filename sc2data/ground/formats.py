"""Format headers: every file and folder sc2data writes names its format and version.

One table of formats, one way to write a header and one check with one message style:
``PATH is not an sc2data KIND`` for a foreign file, ``PATH has KIND format V, not W; REMEDY`` for
one written by another version. The ids are spelled as they have been stored since each format's
first version (existing datasets, pair sets and checkpoints must keep reading), so the older
hyphenated ids of shards and datasets stay; formats added later use the dotted form
``sc2data.NAME``.

A record's header says whose it is; its *shape* (:data:`Shape`: which fields, of which JSON
types) says it can be read: :func:`check_record` turns valid JSON of the wrong shape (``[]``,
``null``, a field of the wrong type) into the same one-line error, before any reader looks inside.
And every JSON record is parsed by :func:`loads`, which refuses what no sc2data record holds and
what would otherwise end as a traceback further on: nesting deeper than :data:`MAX_DEPTH`,
``NaN``/``Infinity`` (or a number too large to be finite) and integers beyond 64 bits.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.vocab import SPLITS

Shape = type | tuple[type, ...] | dict[str, "Shape"] | list["Shape"]
"""What a JSON record must look like: a type or a tuple of types (``int`` never takes a bool,
``float`` takes an int), ``[S]`` a list of S, ``{key: S}`` an object holding those keys (more are
allowed; ``"key?"`` may be absent; ``"*"`` is every value of the object)."""

_WORDS = {dict: "an object", list: "a list", str: "a string", int: "an integer",
          float: "a number", bool: "true or false", type(None): "null"}


MAX_DEPTH = 64
"""The deepest nesting of objects and lists a record may have (sc2data's own stay under 10)."""


class RecordError(ValueError):
    """A JSON text that is no record sc2data can read; the message says why in a few words."""


def _finite(text: str) -> float:
    value = float(text)
    if value != value or value in (float("inf"), float("-inf")):
        raise RecordError(f"it holds the number {text}, too large to be finite")
    return value


def _no_constant(name: str) -> Any:
    raise RecordError(f"it holds {name}, not a finite number")


def _int64(text: str) -> int:
    value = int(text)
    if not -(1 << 63) <= value < 1 << 64:
        raise RecordError(f"it holds the integer {text[:20]}…, beyond 64 bits")
    return value


def loads(text: str | bytes, *, finite: bool = True) -> Any:
    """``json.loads`` for records: a :class:`RecordError` (a ``ValueError``, as every reader
    already catches) for invalid JSON, nesting deeper than :data:`MAX_DEPTH`, a non-finite number
    (unless not ``finite``: a metrics row's NaN loss is a measurement) or an integer beyond 64
    bits, rather than a ``RecursionError`` here or an ``OverflowError`` where the value is
    used."""
    try:
        value = json.loads(text, parse_int=_int64, **(
            {"parse_float": _finite, "parse_constant": _no_constant} if finite else {}))
    except RecursionError:
        raise RecordError(f"it is nested deeper than {MAX_DEPTH} levels") from None
    level, depth = [value], 0
    while level:  # breadth first, so that no walk here recurses either
        depth += 1
        if depth > MAX_DEPTH:
            raise RecordError(f"it is nested deeper than {MAX_DEPTH} levels")
        level = [v for c in level if isinstance(c, (dict, list))
                 for v in (c.values() if isinstance(c, dict) else c)
                 if isinstance(v, (dict, list))]
    return value


def _word(value: Any) -> str:
    return next((w for t, w in _WORDS.items() if type(value) is t), type(value).__name__)


def shape_fault(value: Any, shape: Shape, at: str = "") -> str | None:
    """Where ``value`` departs from ``shape``, in words (None if it fits)."""
    where = f"{at} is" if at else "it holds"
    if isinstance(shape, dict):
        if not isinstance(value, dict):
            return f"{where} {_word(value)}, not an object"
        for key, sub in shape.items():
            name = key.rstrip("?")
            items = value.items() if name == "*" else [(name, value[name])] if name in value \
                else []
            if not items and name != "*" and not key.endswith("?"):
                return f"{at or 'it'} lacks the field {name!r}"
            for k, v in items:
                fault = shape_fault(v, sub, f"{at}.{k}" if at else str(k))
                if fault:
                    return fault
        return None
    if isinstance(shape, list):
        if not isinstance(value, list):
            return f"{where} {_word(value)}, not a list"
        faults = (shape_fault(v, shape[0], f"{at}[{i}]") for i, v in enumerate(value))
        return next((f for f in faults if f), None)
    types = shape if isinstance(shape, tuple) else (shape,)
    fits = type(value) in types or (type(value) is int and float in types)
    return None if fits else f"{where} {_word(value)}, not " + " or ".join(
        _WORDS.get(t, t.__name__) for t in types)


def check_record(value: Any, shape: Shape, where: object, remedy: str) -> None:
    """One-line error unless ``value`` (a parsed JSON record read from ``where``) has ``shape``."""
    fault = shape_fault(value, shape)
    if fault:
        raise Sc2DataError(f"{where} is not a record sc2data can read ({fault}); {remedy}")


@dataclass(frozen=True)
class Format:
    """One stored format: its id, current version, what a user calls it, and what to do about an
    old one."""

    id: str
    version: int
    kind: str
    remedy: str
    reads: tuple[int, ...] = ()
    """Older versions still read (and verified), never written into."""
    shape: Shape | None = None
    """What a record of this format holds beyond its header (JSON records only)."""

    def header(self) -> dict[str, Any]:
        """The two fields that open every record of this format."""
        return {"format": self.id, "format_version": self.version}

    def check(self, found: Mapping[str, Any] | Any, where: object) -> int:
        """The version of ``found`` (a dict, HDF5 attrs, …); a one-line error unless it carries
        this header with the current version or one still read."""
        get = getattr(found, "get", None)
        if get is None or get("format") != self.id:
            raise Sc2DataError(f"{where} is not an sc2data {self.kind}")
        version = get("format_version")
        if version != self.version and version not in self.reads:
            raise Sc2DataError(f"{where} has {self.kind} format {version}, not {self.version}; "
                               f"{self.remedy}")
        if self.shape is not None:
            check_record(found, self.shape, where, self.remedy)
        return int(version)


SHARD = Format("sc2data-shard", 4, "shard", "regenerate it with this sc2data", reads=(2, 3))
"""2: frames in blocks (one HDF5 dataset per group and dtype). 3: its ``settings`` attribute
leaves out the dataset's episode count, so a shard's bytes do not depend on how many episodes
follow it and a dataset grows without rewriting its full shards. 4: each frame's
``available_actions`` kept as a packed mask (``/available_actions``)."""
DATASET = Format("sc2data-dataset", 4, "dataset", "regenerate it with this sc2data", reads=(2, 3),
                 shape={"schema": dict,  # its own shape: sc2data.schema
                        "settings": {"episodes?": (int, type(None))},  # the codec: data.dataset
                        "versions?": dict})
"""``dataset.json``; dataset format V holds shards of format V (2, 3 and 4). A dataset of an
older format still read is readable and verifiable (a format 3 one has no action masks), but a
rollout does not add to it."""
PACKED = Format("sc2data.packed", 1, "packed split", "rerun sc2data pair")
PAIRSET = Format("sc2data.pairset", 1, "pair set", "rerun sc2data pair", shape={
    "schema": dict,
    "commands": [{"id": str, "text": str, "paraphrases?": [str], "train_paraphrases?": [str]}],
    "fingerprint": str,
    "splits": {s: {"states": int} for s in SPLITS},
    "counts?": {"*": {"*": int}},
    "recipe_name?": str, "seed?": int, "recipe?": {"split?": {"method?": str}},
    "identity?": dict, "labels?": {"rules?": [dict]}, "versions?": dict,
})
"""``pairset.json`` (``docs/pairset.md``)."""
CHECKPOINT = Format("sc2data.mem", 1, "model checkpoint", "retrain the model")
