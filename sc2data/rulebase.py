"""The Rule API: a labelling rule says, for each two-frame stack, whether a command was satisfied.

A rule is a small pure object. It declares

* ``id`` — a stable snake_case identifier (``build_supply_depot``), the key of its labels;
* ``command`` — the canonical natural-language text (``"build a supply depot"``);
* ``version`` — an integer, bumped whenever the rule's meaning changes (old labels stay apart);
* ``requires`` — the schema keys it reads (``"screen/unit_type"``, ``"player"``, …), so the
  labeller reads only those from storage and refuses a dataset that lacks one;

and answers ``rule(batch) -> np.ndarray`` of shape ``(B,)`` and dtype ``bool`` for a
:class:`~sc2data.schema.StackBatch` of B stacks. It reads the batch only by pysc2 names
(``batch.layer("screen/unit_type")``, ``batch.vector("player", "food_workers")``), so the same rule
labels the embedded simulator's frames and the real game's observations (``Schema.extract``)
unchanged. No I/O, no state: a test builds two frames by hand (:func:`blank_frame`,
:func:`stack`) and calls it.

Two ways to write one: subclass :class:`Rule`, or decorate a function with :func:`rule`.
"""

from __future__ import annotations

import re
import weakref
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sc2data.schema import VECTORS, Schema, StackBatch, layer

RULE_ID = re.compile(r"^[a-z][a-z0-9]*(?:_[a-z0-9]+)*$")
"""Rule ids are snake_case: lowercase words of letters and digits joined by single underscores."""


class Rule:
    """Base class of a labelling rule; subclasses set the four attributes and ``__call__``.

    The attributes may be class attributes (the usual case) or set per instance by a subclass's
    ``__init__`` (a parametrised rule). A subclass must be constructible with no arguments to be
    listed by class in a plugin's ``RULES``; otherwise list an instance.
    """

    id: str
    command: str
    version: int = 1
    requires: tuple[str, ...] = ()

    def __call__(self, batch: StackBatch) -> np.ndarray:
        """``(B,)`` bool: which of the batch's stacks satisfy the command."""
        raise NotImplementedError(f"{type(self).__name__} does not implement __call__")

    def __repr__(self) -> str:
        return f"<rule {getattr(self, 'id', '?')} v{getattr(self, 'version', '?')}: " \
               f"{getattr(self, 'command', '?')!r}>"


class FunctionRule(Rule):
    """A rule made from a plain function by :func:`rule`."""

    def __init__(self, fn: Callable[[StackBatch], np.ndarray], *, id: str, command: str,
                 version: int, requires: Iterable[str]) -> None:
        self.fn = fn
        self.id = id
        self.command = command
        self.version = version
        self.requires = tuple(requires)
        self.__doc__ = fn.__doc__
        self.__module__ = fn.__module__

    def __call__(self, batch: StackBatch) -> np.ndarray:
        return self.fn(batch)


def rule(*, id: str, command: str, requires: Iterable[str], version: int = 1
         ) -> Callable[[Callable[[StackBatch], np.ndarray]], FunctionRule]:
    """Decorator turning ``fn(batch) -> (B,) bool`` into a :class:`Rule` object.

    >>> @rule(id="gain_minerals", command="gain minerals", requires=["player"])
    ... def gain_minerals(batch):
    ...     return rose(batch.vector("player", "minerals"))
    """
    def wrap(fn: Callable[[StackBatch], np.ndarray]) -> FunctionRule:
        return FunctionRule(fn, id=id, command=command, version=version, requires=requires)
    return wrap


# -- helpers rules are built from ------------------------------------------------------------------

def rose(pair: np.ndarray) -> np.ndarray:
    """``(B, 2)`` previous/current values → ``(B,)`` bool: the value went up."""
    return pair[:, 1] > pair[:, 0]


def fell(pair: np.ndarray) -> np.ndarray:
    """``(B, 2)`` previous/current values → ``(B,)`` bool: the value went down."""
    return pair[:, 1] < pair[:, 0]


def change(pair: np.ndarray) -> np.ndarray:
    """``(B, 2)`` previous/current values → ``(B,)`` signed difference (current − previous)."""
    return pair[:, 1].astype(np.int64) - pair[:, 0]


def count_true(mask: np.ndarray) -> np.ndarray:
    """``(B, …)`` bool → ``(B,)`` number of true cells per batch row (fast popcount path)."""
    b = mask.shape[0]
    flat = mask.reshape(b, -1) if b else mask.reshape(0, int(np.prod(mask.shape[1:])))
    if flat.shape[1] % 8 == 0 and flat.flags.c_contiguous:
        # Bools are bytes of 0/1: a uint64 holds 8 of them and its bit count is their sum.
        return np.bitwise_count(flat.view(np.uint64)).sum(axis=1, dtype=np.int64)
    return np.count_nonzero(flat, axis=1).astype(np.int64)


def is_any(plane: np.ndarray, values: Sequence[int]) -> np.ndarray:
    """Elementwise ``plane ∈ values`` for a handful of ids (faster than ``np.isin`` here)."""
    mask = plane == values[0]
    for v in values[1:]:
        mask |= plane == v
    return mask


def pixel_count(plane: np.ndarray, values: Sequence[int]) -> np.ndarray:
    """``(B, 2, H, W)`` categorical layer → ``(B, 2)``: pixels per frame with a value in
    ``values``."""
    b = plane.shape[0]
    mask = is_any(plane.reshape(b * 2, *plane.shape[2:]), values)
    return count_true(mask).reshape(b, 2)


@dataclass(frozen=True)
class Appeared:
    """The pixels of a categorical layer that went from empty (0) to some unit between the frames.

    Sparse — a step adds a few dozen such pixels to a 64×64 screen — so every rule that asks
    about new footprints of some unit types shares one pass over the layer.
    """

    rows: np.ndarray
    """Batch row (stack index) of each such pixel."""
    values: np.ndarray
    """Its value (unit type id) in the current frame."""
    size: int
    """Batch size B."""

    def count(self, values: Sequence[int]) -> np.ndarray:
        """``(B,)`` how many of each stack's new pixels hold one of ``values``."""
        return np.bincount(self.rows[is_any(self.values, values)], minlength=self.size)


_appeared_cache: weakref.WeakKeyDictionary[StackBatch, dict[str, Appeared]] = \
    weakref.WeakKeyDictionary()


def appeared(batch: StackBatch, key: str) -> Appeared:
    """The new-on-empty-ground pixels of layer ``key`` (cached per batch: treat batches as
    read-only once rules have seen them)."""
    per_batch = _appeared_cache.setdefault(batch, {})
    if key not in per_batch:
        plane = batch.layer(key)
        b = plane.shape[0]
        hw = int(np.prod(plane.shape[2:]))
        mask = plane[:, 0] == 0
        mask &= plane[:, 1] != 0
        idx = np.flatnonzero(mask)
        rows = idx // hw
        values = plane.reshape(b, 2, hw)[rows, 1, idx - rows * hw]
        per_batch[key] = Appeared(rows, values, b)
    return per_batch[key]


def appeared_pixels(batch: StackBatch, key: str, values: Sequence[int]) -> np.ndarray:
    """``(B,)`` pixels of layer ``key`` that became one of ``values`` on ground that was empty
    (value 0) in the previous frame.

    A new building appears on empty ground; a unit walking off a building uncovers pixels that were
    the unit's, not empty, so it adds nothing here — which is what makes this robust where a plain
    count of building pixels is not.
    """
    return appeared(batch, key).count(values)


# -- building stacks by hand (tests, validation, users' own checks) -----------------------------

def _vector_keys() -> dict[str, int]:
    return {v.name: v.size for v in VECTORS}


def is_schema_key(key: str) -> bool:
    """True for ``screen/<pysc2 layer>``, ``minimap/<pysc2 layer>`` or a kept vector's name."""
    group, _, name = key.partition("/")
    if name:
        if group not in ("screen", "minimap"):
            return False
        try:
            layer(group, name)  # type: ignore[arg-type]
        except ValueError:
            return False
        return True
    return key in _vector_keys()


def schema_for(keys: Iterable[str]) -> Schema:
    """The smallest :class:`Schema` holding the given layer keys (vectors are always described)."""
    keys = list(keys)
    return Schema.from_names([k.split("/", 1)[1] for k in keys if k.startswith("screen/")],
                             [k.split("/", 1)[1] for k in keys if k.startswith("minimap/")])


def blank_frame(schema: Schema | None = None) -> dict[str, np.ndarray]:
    """One all-zero frame with every key of ``schema`` (default: the paper's), dtypes as stored."""
    schema = schema or Schema.paper()
    frame: dict[str, np.ndarray] = {}
    for l in schema.layers:
        n = schema.size(l.group)
        frame[l.key] = np.zeros((n, n), l.dtype)
    for v in schema.vectors:
        frame[v.name] = np.zeros(v.size, v.dtype)
    return frame


def set_field(frame: dict[str, np.ndarray], vector: str, field: str, value: int) -> None:
    """Set one named field of a frame's vector, e.g. ``("player", "food_workers", 13)``."""
    fields = next(v.fields for v in VECTORS if v.name == vector)
    frame[vector][fields.index(field)] = value


SCREEN_PX_PER_UNIT = 64 / 24
"""Screen pixels per world unit at 64×64 (the screen spans 24 world units)."""


def paint_disk(frame: dict[str, np.ndarray], key: str, center: tuple[float, float],
               radius: float, value: int) -> int:
    """Draw a unit into a frame's layer as the game does: a filled disk sampled at pixel centres.

    ``center`` is ``(x, y)`` in pixels and ``radius`` in pixels (a unit's radius ×
    :data:`SCREEN_PX_PER_UNIT`); a marine (radius 0.375) comes out 2×2, a supply depot ~30 px.
    Returns the number of pixels painted.
    """
    plane = frame[key]
    h, w = plane.shape
    ys, xs = np.mgrid[0:h, 0:w]
    disk = (xs + 0.5 - center[0]) ** 2 + (ys + 0.5 - center[1]) ** 2 <= radius ** 2
    plane[disk] = value
    return int(disk.sum())


def stack(pairs: Sequence[tuple[Mapping[str, np.ndarray], Mapping[str, np.ndarray]]],
          schema: Schema | None = None) -> StackBatch:
    """A :class:`StackBatch` from ``(previous, current)`` frame dicts, as ``Schema.extract`` gives.

    Without ``schema``, the batch's schema is the smallest one holding the frames' layer keys.
    """
    if not pairs:
        raise ValueError("stack() needs at least one (previous, current) pair")
    keys = list(pairs[0][0])
    schema = schema or schema_for(keys)
    arrays = {k: np.stack([np.stack([np.asarray(p[k]), np.asarray(c[k])]) for p, c in pairs])
              for k in keys}
    return StackBatch(arrays, schema)


def synthetic_batch(requires: Iterable[str], size: int = 5, seed: int = 0) -> StackBatch:
    """Random stacks holding exactly the keys in ``requires``, values within each layer's scale.

    The registry calls every rule on one at load: a rule that reads a key it did not declare, or
    answers with the wrong shape or dtype, is caught before any data is touched.
    """
    requires = list(dict.fromkeys(requires))
    schema = schema_for(requires)
    rng = np.random.default_rng(seed)
    by_key = {l.key: l for l in schema.layers}
    sizes = _vector_keys()
    arrays: dict[str, np.ndarray] = {}
    for key in requires:
        if key in by_key:
            l = by_key[key]
            n = schema.size(l.group)
            arrays[key] = rng.integers(0, l.scale, (size, 2, n, n)).astype(l.dtype)
        else:
            arrays[key] = rng.integers(0, 200, (size, 2, sizes[key])).astype(np.int32)
    return StackBatch(arrays, schema)


def describe(obj: Any) -> str:
    """``id`` of a rule-like object for messages, or its repr where it has none."""
    rid = getattr(obj, "id", None)
    return repr(rid) if isinstance(rid, str) else repr(obj)
