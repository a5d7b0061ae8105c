"""The state encoder at inference on a CPU: the same function as ``StateEncoder``, on fewer
channels.

The scorer (a reward an RL loop calls every env step) spends its time building the one-hot image
and in the first convolution, which sees 92 screen and 66 minimap channels of which a
BuildMarines batch uses about a third. The first convolution is linear in its input channels,
so for each batch it is rebuilt to read only the channels that batch needs:

- a channel that is zero in every stack of the batch contributes nothing, and is dropped;
- a categorical layer's cell shares sum to 1 in each frame, so the share of one id *b* of it
  (the smallest id present in the batch, usually the background) is 1 − Σ the others':
  ``conv(x) = Σ_{c≠b} (W_c − W_b) ∗ x_c + Σ W_b``, the constant folded into the bias; a layer
  that shows one id in the whole batch vanishes;
- a scalar layer constant over the batch (the simulator's flat height map) folds into the bias;
- a layer showing the same image in every stack and frame (a map's terrain, its fog, the
  minimap's camera box) adds the same map to the convolution's output every time: once an image
  has come twice, that share is computed on one frame and cached by the image's bytes;
- a cell's shares and means are pixel counts and sums, which the image holds, with the 1/p² and
  the pysc2 scale folded into the kernel instead.

Each channel's cell counts come from one comparison and a few adds of 64-bit words, four or eight
pixels to a word (``_cell_totals``); no float image of every channel is ever built. Distances
agree with the training path's to float rounding (tests/model/test_infer.py: within 1e-5);
measured in BENCHMARKS.md ("The MEM as a reward").
The other layers of the towers, the non-spatial branch and the head are the model's own modules.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from sc2data.ground.errors import Sc2DataError
from sc2data.model.mem import EmbeddedConv, SpatialInput, StateEncoder


@dataclass(frozen=True)
class _Categorical:
    key: str
    col: int
    """The layer's first channel within a frame's block."""
    n: int
    lut: np.ndarray | None
    """raw id → compact index (uint8), or None where they are equal."""


class _Group:
    """One tower's first convolution, rebuilt per batch from the channels the batch uses."""

    def __init__(self, inp: SpatialInput, tower: nn.Sequential) -> None:
        first = tower[0]
        if isinstance(first, EmbeddedConv):  # conv(W, embed(x)) = conv(W·E, x): fold E once
            with torch.no_grad():
                w = torch.einsum("odyx,cd->ocyx", first.conv.weight, first.mixing())
            conv = first.conv
        else:
            assert isinstance(first, nn.Conv2d)
            conv, w = first, first.weight.detach()
        self.weight = w.float().contiguous()
        self.bias = conv.bias.detach().float() if conv.bias is not None \
            else torch.zeros(w.shape[0])
        self.stride = conv.stride
        self.rest = tower[1:]
        self.pool = inp.pool
        n_s = len(inp.scalar_keys)
        self.per_frame = n_s + inp.cat_width
        self.scalars = [(k, j, float(s)) for j, (k, s) in
                        enumerate(zip(inp.scalar_keys, inp.inv_scale.tolist()))]
        self.cats: list[_Categorical] = []
        for i, (key, n) in enumerate(zip(inp.cat_keys, inp.sizes)):
            seg = inp._lut[inp._raw_offsets[i]:][:_scale(inp, i)].astype(np.int64) - \
                int(inp.first[i])
            lut = None if np.array_equal(seg, np.arange(len(seg))) else seg.astype(
                np.uint8 if n <= 256 else np.int16)
            self.cats.append(_Categorical(key, n_s + int(inp.first[i]), n, lut))
        self.keys = [k for k, _, _ in self.scalars] + [c.key for c in self.cats]
        self._cache: dict[tuple[str, str, tuple[int, ...], bytes], torch.Tensor] = {}
        self._seen: set[tuple[str, str, tuple[int, ...], bytes]] = set()

    def __call__(self, arrays: Mapping[str, np.ndarray]) -> torch.Tensor:
        """Stacks by key ``(B, 2, H, W)`` → the tower's output ``(B, features)``."""
        b, _, hh, ww = arrays[self.keys[0]].shape
        p = self.pool
        if hh % p or ww % p:
            raise Sc2DataError(f"a layer is {hh}×{ww}, not divisible by the pool size {p}")
        varying: dict[str, np.ndarray] = {}
        constant: torch.Tensor | None = None  # the layers the same in every stack and frame
        for key in self.keys:
            x = arrays[key]
            image = _same_image(x)
            c = None if image is None else self._constant(key, x[0, 0], image)
            if c is None:
                varying[key] = x
            else:
                constant = c if constant is None else constant + c
        y = self._first_conv(varying, (b, hh, ww))
        return self.rest(y if constant is None else y + constant)

    def _constant(self, key: str, frame: np.ndarray, image: bytes) -> torch.Tensor | None:
        """The first convolution's share ``(1, C, h, w)`` of a layer showing ``frame`` in every
        stack and both frames (a map's height, its fog; ``image``: its bytes), cached by content;
        None the first time
        an image is seen (it may never come again: at batch 1 a layer often shows the same in
        both frames), when it goes with the other layers."""
        cache_key = (key, frame.dtype.str, frame.shape, image)
        out = self._cache.get(cache_key)
        if out is None:
            if cache_key not in self._seen:
                if len(self._seen) >= _CACHE_SIZE:
                    self._seen.clear()
                self._seen.add(cache_key)
                return None
            if len(self._cache) >= _CACHE_SIZE:
                self._cache.clear()
            one = np.broadcast_to(frame, (1, 2, *frame.shape))
            out = self._first_conv({key: one}, (1, *frame.shape), bias=False)
            self._cache[cache_key] = out
        return out

    def _first_conv(self, arrays: Mapping[str, np.ndarray], shape: tuple[int, int, int],
                    bias: bool = True) -> torch.Tensor:
        """The first convolution over the layers in ``arrays`` (the others read as zero)."""
        p = self.pool
        # per kept channel: its source (B, 2, H, W), the id it counts (None: a scalar's sum), its
        # column in a frame's block, the column subtracted from it (its layer's base; -1: none),
        # the factor folded into the kernel, and the largest value it sums (-1: some negative)
        jobs: list[tuple[np.ndarray, int | None, int, int, float, int]] = []
        fold: list[int] = []  # columns of constant inputs, and their value
        fold_value: list[float] = []
        for key, j, inv_scale in self.scalars:
            if key not in arrays:
                continue
            x = arrays[key]
            lo, hi = x.min(), x.max()
            if lo == hi:  # constant (usually 0): into the bias
                if hi:
                    fold.append(j)
                    fold_value.append(float(hi) * inv_scale)
                continue
            jobs.append((x, None, j, -1, inv_scale / p ** 2, int(hi) if lo >= 0 else -1))
        for cat in self.cats:
            if cat.key not in arrays:
                continue
            u = arrays[cat.key]
            if cat.lut is not None:
                u = np.take(cat.lut, u)
            present = _present(u, cat.n)
            base = int(present[0])
            fold.append(cat.col + base)
            fold_value.append(1.0)
            jobs += [(u, int(c), cat.col + int(c), cat.col + base, 1.0 / p ** 2, 1)
                     for c in present[1:]]
        b, hh, ww = shape
        h, w, n = hh // p, ww // p, max(len(jobs), 1)
        image = (np.empty if jobs else np.zeros)((b, 2, n, h, w), np.float32)  # channel t·n + i
        for i, (src, c, *_, hi) in enumerate(jobs):
            if hi < 0:  # negative values
                _cell_sums(src, p, np.float32, image[:, :, i])
            else:
                _cell_totals(src if c is None else src == c, p, hi, image[:, :, i])
        x = torch.from_numpy(image).view(b, 2 * n, h, w)
        return self._conv(x, jobs, fold, fold_value, with_bias=bias)

    def _conv(self, x: torch.Tensor,
              jobs: list[tuple[np.ndarray, int | None, int, int, float, int]],
              fold: list[int], fold_value: list[float], with_bias: bool = True) -> torch.Tensor:
        """The first convolution on the kept channels, constants in the bias (``with_bias``:
        the layer's own bias too)."""
        c, w = self.per_frame, self.weight
        bias = self.bias.clone() if with_bias else torch.zeros_like(self.bias)
        if fold:
            cols = torch.tensor([t * c + f for t in (0, 1) for f in fold])
            vals = torch.tensor(fold_value * 2, dtype=torch.float32)
            bias += (w[:, cols].sum((2, 3)) * vals).sum(1)
        if not jobs:  # every input constant: x is one zero channel per frame
            return F.conv2d(x, torch.zeros(w.shape[0], 2, *w.shape[2:]), bias, self.stride)
        ext = torch.cat([w, torch.zeros(w.shape[0], 1, *w.shape[2:])], 1)  # column -1: zeros
        p_idx = torch.tensor([t * c + job[2] for t in (0, 1) for job in jobs])
        m_idx = torch.tensor([t * c + job[3] if job[3] >= 0 else -1
                              for t in (0, 1) for job in jobs])
        f = torch.tensor([job[4] for job in jobs] * 2, dtype=torch.float32)
        kernel = (ext[:, p_idx] - ext[:, m_idx]) * f[None, :, None, None]
        return F.conv2d(x, kernel, bias, self.stride)


def _scale(inp: SpatialInput, i: int) -> int:
    """The number of raw ids of categorical layer ``i`` (its segment of the lookup table)."""
    offsets = list(inp._raw_offsets) + [len(inp._lut)]
    return int(offsets[i + 1] - offsets[i])


_CACHE_SIZE = 256
"""Constant layers' first-convolution shares (and images seen once) kept per tower: a few per
map in practice."""


def _same_image(x: np.ndarray) -> bytes | None:
    """The bytes of the image ``x`` ``(B, 2, H, W)`` shows in every stack and frame, or None."""
    first = x[0, 0].tobytes()
    if first != x[-1, -1].tobytes() or (len(x) > 1 and not (x == x[0, 0]).all()):
        return None
    return first


_WORDS_FROM = 1 << 17
"""Pixels from which cell sums go a word at a time (16 stacks of 64×64 layers): below, the
plain strided sums' fewer numpy calls are faster (measured: 9 against 14 µs at one stack, 199
against 138 µs at 64)."""


_BITS = ((8, np.uint8), (16, np.uint16), (32, np.uint32), (64, np.uint64))


def _present(u: np.ndarray, n: int) -> np.ndarray:
    """The sorted compact ids that occur in ``u``."""
    lo, hi = int(u.min()), int(u.max())
    if hi - lo <= 1:  # min and max are all there is (most layers of a BuildMarines batch)
        return np.arange(lo, hi + 1, dtype=np.int64)
    for width, dtype in _BITS:  # one bit per id, OR-reduced, in the narrowest integer
        if n <= width:
            bits = int(np.bitwise_or.reduce(np.left_shift(dtype(1), u, dtype=dtype), axis=None))
            return np.array([c for c in range(n) if bits >> c & 1], np.int64)
    return np.flatnonzero(np.bincount(u.ravel(), minlength=n))


def _cell_sums(x: np.ndarray, p: int, dtype: type, out: np.ndarray) -> None:
    """``(B, 2, H, W)`` → ``out`` ``(B, 2, H/p, W/p)``: the sum over each p×p cell (rows, then
    columns, in ``dtype``)."""
    if p == 1:
        np.copyto(out, x)
        return
    rows = np.add(x[:, :, 0::p], x[:, :, 1::p], dtype=dtype)
    for d in range(2, p):
        rows += x[:, :, d::p]
    np.add(rows[..., 0::p], rows[..., 1::p], out=out)
    for d in range(2, p):
        out += rows[..., d::p]


def _cell_totals(x: np.ndarray, p: int, hi: int, out: np.ndarray) -> None:
    """``(B, 2, H, W)`` non-negative integers (booleans: counts) at most ``hi`` → ``out``: the
    sum over each p×p cell.

    Several pixels at a time, as the lanes of one 64-bit word: 8-bit lanes where a cell's sum
    fits in a byte, else 16-bit ones. Adding rows adds lane by lane (no lane carries into the
    next), then shifted adds sum each p neighbouring lanes into the first, which a mask keeps;
    the word read as p-lane integers is then the cells' sums. Small batches, other sizes and
    types: plain strided sums (``_cell_sums``)."""
    total = hi * p * p
    lane = 8 if total < 1 << 8 else 16 if total < 1 << 16 else 0
    if (p not in (2, 4) or not lane or x.dtype.kind not in "biu" or sys.byteorder != "little"
            or (x.shape[-1] * lane) % 64 or x.size < _WORDS_FROM):
        _cell_sums(x, p, np.float32, out)
        return
    narrow = np.uint8 if lane == 8 else np.uint16
    x = x.view(np.uint8) if x.dtype == np.bool_ else x
    words = np.ascontiguousarray(x, dtype=narrow).view(np.uint64)  # (B, 2, H, W·lane/64)
    rows = np.add(words[:, :, 0::p], words[:, :, 1::p])
    for d in range(2, p):
        rows += words[:, :, d::p]
    shift = lane
    while shift < lane * p:
        rows += rows >> np.uint64(shift)
        shift *= 2
    group = lane * p  # bits of one cell's p lanes
    rows &= np.uint64(sum(((1 << lane) - 1) << g for g in range(0, 64, group)))
    np.copyto(out, rows.view(f"<u{group // 8}"))


class FastStateEncoder:
    """``StateEncoder.forward(model_inputs(...))`` from raw stacks, on a CPU (see the module
    docstring); for ``onehot`` and ``embed`` models."""

    def __init__(self, state: StateEncoder) -> None:
        if any(inp.mode == "scalar" for _, inp in state.groups):
            raise Sc2DataError("the fast path needs a onehot or embed model")
        self.state = state
        self.groups = [(g, _Group(inp, state.towers[g])) for g, inp in state.groups]

    @staticmethod
    def supports(state: StateEncoder) -> bool:
        return all(inp.mode != "scalar" for _, inp in state.groups)

    def __call__(self, arrays: Mapping[str, np.ndarray]) -> torch.Tensor:
        """Raw stacks by schema key → ``(B, dim)`` embeddings (call under inference_mode)."""
        feats = [g(arrays) for _, g in self.groups]
        s = self.state
        if s.nonspatial is not None:
            v = torch.from_numpy(np.concatenate([arrays[n] for n in s.vectors], -1).astype(
                np.float32))
            v = torch.cat([v[:, 0], v[:, 1], v[:, 1] - v[:, 0]], -1)
            feats.append(s.nonspatial(torch.sign(v) * torch.log1p(v.abs())))
        return s.head(torch.cat(feats, 1))


__all__ = ["FastStateEncoder"]
