"""The state schema, described once as data.

A *frame* is one pysc2 observation reduced to what we keep: some screen layers, some minimap
layers and the non-spatial vectors. A *stack* is two consecutive frames (previous, current), the
paper's temporal stack of n=2. Everything that stores, reads, labels or learns from frames derives
its layout from a :class:`Schema`: the HDF5 writer and reader, ``sc2data info``, the rules'
requirements and the model's input channels.

Layers come from pysc2's own tables (``features.SCREEN_FEATURES`` / ``MINIMAP_FEATURES``), so
names, indices, scales and kinds are pysc2's; each layer is kept in the smallest unsigned integer
dtype its scale allows, losslessly.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from sc2data._pysc2 import actions, features
from sc2data.ground.formats import shape_fault
from sc2data.ground.vocab import MINIMAP_SIZE, SCREEN_SIZE

SCHEMA_VERSION = 1
"""Bump when the stored layout changes; readers refuse shards of another version."""


Group = Literal["screen", "minimap"]

PAPER_SCREEN: tuple[str, ...] = (
    "height_map", "visibility_map", "creep", "power", "player_id", "player_relative",
    "unit_type", "selected", "unit_hit_points", "unit_energy", "unit_shields", "unit_density",
    "unit_density_aa",
)
"""pysc2 1.x's 13 screen layers: the paper's screen state (all still exist by name in 4.0)."""

PAPER_MINIMAP: tuple[str, ...] = (
    "height_map", "visibility_map", "creep", "camera", "player_id", "player_relative", "selected",
)
"""pysc2 1.x's 7 minimap layers: the paper's minimap state."""

_TABLES = {"screen": features.SCREEN_FEATURES, "minimap": features.MINIMAP_FEATURES}
_OBS_KEY = {"screen": "feature_screen", "minimap": "feature_minimap"}


@dataclass(frozen=True)
class Layer:
    """One spatial feature layer, as pysc2 defines it."""

    group: Group
    name: str
    index: int
    """Position in pysc2's ``feature_screen`` / ``feature_minimap`` array."""
    scale: int
    """Number of distinct values (pysc2's ``scale``); values lie in ``[0, scale)``."""
    categorical: bool

    @property
    def key(self) -> str:
        return f"{self.group}/{self.name}"

    @property
    def dtype(self) -> np.dtype:
        """Smallest lossless unsigned dtype for this layer's scale."""
        return np.dtype(np.uint8) if self.scale <= 256 else np.dtype(np.uint16)

    @property
    def limit(self) -> int:
        """One past the largest value kept losslessly: the dtype's range, not the scale.

        pysc2's scale is nominal for counts: ``unit_density`` declares 16, yet more units than
        that can stand on one pixel (pysc2 does not clip). Such values still fit the dtype.
        """
        return int(np.iinfo(self.dtype).max) + 1


def layer(group: Group, name: str) -> Layer:
    """Look a layer up in pysc2's table by group and name."""
    table = _TABLES[group]
    try:
        f = getattr(table, name)
    except AttributeError:
        known = ", ".join(f.name for f in table)
        raise ValueError(f"unknown {group} layer {name!r}; pysc2 has: {known}") from None
    return Layer(group, f.name, int(f.index), int(f.scale),
                 f.type == features.FeatureType.CATEGORICAL)


@dataclass(frozen=True)
class Vector:
    """One non-spatial observation vector kept per frame."""

    name: str
    fields: tuple[str, ...]
    dtype: np.dtype = np.dtype(np.int32)

    @property
    def size(self) -> int:
        return len(self.fields)


VECTORS: tuple[Vector, ...] = (
    Vector("player", tuple(f.name for f in features.Player)),
    Vector("score_cumulative", tuple(f.name for f in features.ScoreCumulative)),
    Vector("game_loop", ("game_loop",)),
)
"""Non-spatial vectors, by pysc2's field names. ``player`` (11) plus ``score_cumulative`` (13) is
our reading of the paper's "13 non-spatial features" gap: we keep both, whole."""

AVAILABLE = Vector("available_actions", tuple(f.name for f in actions.FUNCTIONS), np.dtype(bool))
"""pysc2's ``available_actions`` of a frame as a mask over ``actions.FUNCTIONS`` (``mask[f]``:
function ``f`` could be called in that frame): the action masks of offline RL. Kept for every
frame of a dataset (shard format 4 on), beside the frames rather than in a :class:`Block`, so the
model, rules and pair sets see the same frame keys as before; older datasets have none."""


@dataclass(frozen=True)
class Block:
    """Frame keys stored together, one HDF5 dataset per block (``/frames/<name>``).

    Layers of one group (one image size) and one dtype are stacked along a layer axis, frame
    shape ``(layers, H, W)``; vectors of one dtype are laid end to end, frame shape ``(fields,)``.
    A stack of all keys then touches four chunks instead of one per key (BENCHMARKS.md).
    """

    name: str
    """Dataset name: ``screen_uint8``, ``screen_uint16``, ``minimap_uint8``, ``vectors_int32``."""
    keys: tuple[str, ...]
    frame_shape: tuple[int, ...]
    dtype: np.dtype
    parts: tuple[slice | int, ...]
    """Where each key sits along the block's first frame axis: a layer index, a vector's slice."""

    def part(self, key: str) -> slice | int:
        return self.parts[self.keys.index(key)]


@dataclass(frozen=True)
class Schema:
    """Which layers and vectors a dataset keeps, in which order."""

    screen: tuple[Layer, ...]
    minimap: tuple[Layer, ...]
    vectors: tuple[Vector, ...] = VECTORS
    screen_size: int = SCREEN_SIZE
    minimap_size: int = MINIMAP_SIZE
    version: int = SCHEMA_VERSION

    @classmethod
    def from_names(cls, screen: Iterable[str], minimap: Iterable[str]) -> Schema:
        return cls(tuple(layer("screen", n) for n in screen),
                   tuple(layer("minimap", n) for n in minimap))

    @classmethod
    def paper(cls) -> Schema:
        """The paper's 13 screen + 7 minimap layers (the default)."""
        return cls.from_names(PAPER_SCREEN, PAPER_MINIMAP)

    @classmethod
    def full(cls) -> Schema:
        """All 27 screen + 11 minimap layers of pysc2 4.0."""
        return cls.from_names((f.name for f in features.SCREEN_FEATURES),
                              (f.name for f in features.MINIMAP_FEATURES))

    @classmethod
    def named(cls, name: str) -> Schema:
        """A preset by name: ``paper`` or ``full``."""
        presets = {"paper": cls.paper, "full": cls.full}
        if name not in presets:
            raise ValueError(f"unknown layer set {name!r}; choose one of: {', '.join(presets)}")
        return presets[name]()

    @property
    def layers(self) -> tuple[Layer, ...]:
        return self.screen + self.minimap

    def group(self, group: Group) -> tuple[Layer, ...]:
        return self.screen if group == "screen" else self.minimap

    def size(self, group: Group) -> int:
        return self.screen_size if group == "screen" else self.minimap_size

    def keys(self) -> tuple[str, ...]:
        """Every array key a frame carries: ``screen/<layer>``, ``minimap/<layer>``, vectors."""
        return tuple(l.key for l in self.layers) + tuple(v.name for v in self.vectors)

    def blocks(self) -> tuple[Block, ...]:
        """How frames are stored: the keys grouped by (group, dtype), in key order."""
        out: list[Block] = []
        for group in ("screen", "minimap"):
            side = self.size(group)
            for dtype in sorted({l.dtype for l in self.group(group)}, key=lambda d: d.itemsize):
                ls = [l for l in self.group(group) if l.dtype == dtype]
                out.append(Block(f"{group}_{dtype.name}", tuple(l.key for l in ls),
                                 (len(ls), side, side), dtype, tuple(range(len(ls)))))
        for dtype in sorted({v.dtype for v in self.vectors}, key=lambda d: d.itemsize):
            vs = [v for v in self.vectors if v.dtype == dtype]
            ends = np.cumsum([v.size for v in vs]).tolist()
            out.append(Block(f"vectors_{dtype.name}", tuple(v.name for v in vs), (ends[-1],),
                             dtype, tuple(slice(e - v.size, e) for v, e in zip(vs, ends))))
        return tuple(out)

    def block_of(self, key: str) -> Block:
        """The storage block holding ``key``."""
        for b in self.blocks():
            if key in b.keys:
                return b
        raise KeyError(f"{key!r} is not a key of this schema; keys: {', '.join(self.keys())}")

    def frame_bytes(self) -> int:
        """Uncompressed bytes of one frame."""
        spatial = sum(l.dtype.itemsize * self.size(l.group) ** 2 for l in self.layers)
        return spatial + sum(v.dtype.itemsize * v.size for v in self.vectors)

    def extract(self, obs: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """Reduce one pysc2 observation to this schema's arrays (lossless, range-checked)."""
        out: dict[str, np.ndarray] = {}
        for group in ("screen", "minimap"):
            planes = np.asarray(obs[_OBS_KEY[group]])
            for l in self.group(group):
                plane = planes[l.index]
                if plane.size and (plane.min() < 0 or plane.max() >= l.limit):
                    raise ValueError(f"{l.key} holds values outside [0, {l.limit})")
                out[l.key] = plane.astype(l.dtype, copy=False)
        for v in self.vectors:
            out[v.name] = np.asarray(obs[v.name]).astype(v.dtype, copy=False).reshape(v.size)
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-able description, stored in every shard and dataset record."""
        return {
            "version": self.version,
            "screen": [l.name for l in self.screen],
            "minimap": [l.name for l in self.minimap],
            "vectors": {v.name: list(v.fields) for v in self.vectors},
            "screen_size": self.screen_size,
            "minimap_size": self.minimap_size,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Schema:
        """Inverse of :meth:`to_dict`; refuses another schema version, or another shape."""
        fault = shape_fault(d, {})
        version = None if fault else d.get("version")
        if not fault and version != SCHEMA_VERSION:
            raise SchemaError(f"schema version {version} is not the supported version "
                              f"{SCHEMA_VERSION}; regenerate the data with this sc2data")
        fault = fault or shape_fault(d, {"screen": [str], "minimap": [str], "vectors": dict})
        if fault:
            raise SchemaError(f"the schema is not one sc2data wrote ({fault})")
        schema = cls.from_names(d["screen"], d["minimap"])
        if d.get("vectors") != {v.name: list(v.fields) for v in schema.vectors}:
            raise SchemaError("the stored non-spatial vectors differ from this pysc2's")
        return schema


Index = int | np.integer | slice | Sequence[int] | np.ndarray
"""What selects stacks of a :class:`StackBatch` or a dataset: a position, a slice, positions or a
boolean mask."""


def positions(index: Index, n: int) -> np.ndarray | slice:
    """``index`` into ``n`` items as non-negative int64 positions (a slice stays a slice of
    ``range(n)``, normalised); negative positions count from the end, as in numpy."""
    if isinstance(index, slice):
        return slice(*index.indices(n))
    if isinstance(index, (bool, np.bool_)):
        raise TypeError("a stack index must be an int, a slice, positions or a boolean mask")
    if isinstance(index, (int, np.integer)):
        i = int(index)
        if not -n <= i < n:
            raise IndexError(f"stack {i} is out of range for {n} stacks")
        i %= n
        return slice(i, i + 1)
    arr = np.asarray(index)
    if arr.dtype == bool:
        if arr.shape != (n,):
            raise IndexError(f"a boolean mask must have shape ({n},), not {arr.shape}")
        return np.flatnonzero(arr)
    if arr.size == 0:
        return np.zeros(0, np.int64)
    if arr.ndim != 1 or not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"stack positions must be a 1-d array of ints, not {arr.dtype} "
                        f"{arr.shape}")
    if arr.min() < -n or arr.max() >= n:
        raise IndexError(f"stack positions must lie in [{-n}, {n})")
    return arr.astype(np.int64) % n if n else arr.astype(np.int64)


class SchemaError(ValueError):
    """Data whose schema this version of sc2data cannot read."""


class MissingLayerError(KeyError):
    """A stack batch lacks a layer or vector that a consumer (rule, model) needs."""

    def __str__(self) -> str:  # KeyError quotes its argument; we want a plain sentence.
        return str(self.args[0])


class StackBatch:
    """B two-frame stacks, read by pysc2 name: the contract between storage, rules and model.

    ``arrays`` maps each key of a :class:`Schema` (``screen/unit_type``, ``player``, …) to an
    array of shape ``(B, 2, …)``: index 0 along axis 1 is the previous frame, 1 the current one.
    """

    def __init__(self, arrays: Mapping[str, np.ndarray], schema: Schema) -> None:
        self.arrays = dict(arrays)
        self.schema = schema
        sizes = {a.shape[0] for a in self.arrays.values()}
        if len(sizes) > 1:
            raise ValueError(f"stack arrays disagree on batch size: {sorted(sizes)}")
        self.size = sizes.pop() if sizes else 0

    def __len__(self) -> int:
        return self.size

    def __repr__(self) -> str:
        """Shapes and dtypes per key, never the arrays themselves."""
        lines = "".join(f"\n  {k}: {tuple(a.shape)} {a.dtype}" for k, a in self.arrays.items())
        return f"StackBatch(size={self.size}, keys={len(self.arrays)}{lines})"

    def __getitem__(self, index: Index) -> StackBatch:
        """Stacks by position: an int gives a batch of one (so any result feeds a rule or the
        model as it is); a slice, an array of positions or a boolean mask, a batch of those."""
        rows = positions(index, self.size)
        return StackBatch({k: a[rows] for k, a in self.arrays.items()}, self.schema)

    def __iter__(self) -> Iterator[StackBatch]:
        """Each stack in turn, as a batch of one."""
        for i in range(self.size):
            yield self[i]

    def layer(self, key: str) -> np.ndarray:
        """``(B, 2, H, W)`` array of ``screen/<name>`` or ``minimap/<name>``."""
        try:
            return self.arrays[key]
        except KeyError:
            raise MissingLayerError(f"the data has no layer {key!r} (stored: "
                                    f"{', '.join(l.key for l in self.schema.layers)}); roll out "
                                    f"again with a layer set that keeps it") from None

    def vector(self, name: str, field: str) -> np.ndarray:
        """``(B, 2)`` array of one field of a non-spatial vector, e.g.
        ``("player", "minerals")``."""
        for v in self.schema.vectors:
            if v.name == name and field in v.fields and name in self.arrays:
                return self.arrays[name][:, :, v.fields.index(field)]
        raise MissingLayerError(f"the data has no vector field {name}.{field}")
