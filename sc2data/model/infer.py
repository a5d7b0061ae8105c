"""The state encoder at inference on a CPU: the same function as ``StateEncoder``, on fewer channels.

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
  minimap's camera box) adds the same map to the convolution's output every time: that share is
  computed once, on one frame, and cached by the image's bytes;
- a cell's shares and means are pixel counts and sums, which the image holds, with the 1/p² and
  the pysc2 scale folded into the kernel instead.

Each channel's cell counts come from one comparison and a few adds of 64-bit words, eight pixels
to a word (``_cell_counts``); no float image of every channel is ever built. Distances agree with the training path's to float rounding
(tests/model/test_infer.py: within 1e-5); measured in BENCHMARKS.md ("The MEM as a reward").
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

from sc2data.errors import Sc2DataError
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
        self._cache: dict[tuple[str, str, bytes], torch.Tensor] = {}

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
            if _same_in_every_frame(x):
                c = self._constant(key, x[0, 0])
                constant = c if constant is None else constant + c
            else:
                varying[key] = x
        y = self._first_conv(varying, (b, hh, ww))
        return self.rest(y if constant is None else y + constant)

    def _constant(self, key: str, frame: np.ndarray) -> torch.Tensor:
        """The first convolution's share ``(1, C, h, w)`` of a layer showing ``frame`` in every
        stack and both frames (a map's height, its fog), cached by content."""
        cache_key = (key, frame.dtype.str, frame.tobytes())
        out = self._cache.get(cache_key)
        if out is None:
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
        # column in a frame's block, the column subtracted from it (its layer's base; -1: none)
        # and the factor folded into the kernel
        jobs: list[tuple[np.ndarray, int | None, int, int, float]] = []
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
            jobs.append((x, None, j, -1, inv_scale / p ** 2))
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
            jobs += [(u, int(c), cat.col + int(c), cat.col + base, 1.0 / p ** 2)
                     for c in present[1:]]
        b, hh, ww = shape
        h, w, n = hh // p, ww // p, max(len(jobs), 1)
        image = (np.empty if jobs else np.zeros)((b, 2, n, h, w), np.float32)  # channel t·n + i
        for i, (src, c, *_) in enumerate(jobs):
            if c is None:
                _cell_sums(src, p, np.float32, image[:, :, i])
            else:
                _cell_counts(src == c, p, image[:, :, i])
        x = torch.from_numpy(image).view(b, 2 * n, h, w)
        return self._conv(x, jobs, fold, fold_value, with_bias=bias)

    def _conv(self, x: torch.Tensor, jobs: list[tuple[np.ndarray, int | None, int, int, float]],
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
"""Constant layers' first-convolution shares kept per tower (a few per map in practice)."""


def _same_in_every_frame(x: np.ndarray) -> bool:
    """``x`` ``(B, 2, H, W)`` shows the same image in every stack and frame."""
    return x[0, 0].tobytes() == x[-1, -1].tobytes() and bool((x == x[0, 0]).all())


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


_LANES = {2: (np.uint16, 0x00FF00FF00FF00FF), 4: (np.uint32, 0x000000FF000000FF)}
"""Per pool size: the lane holding a cell's count in a 64-bit word, and the mask of its byte."""


def _cell_counts(mask: np.ndarray, p: int, out: np.ndarray) -> None:
    """``(B, 2, H, W)`` booleans → ``out``: the number set in each p×p cell.

    Eight pixels at a time as the bytes of one 64-bit word: adding rows adds bytewise (a byte
    counts at most p² ≤ 16, so it never carries into the next), then shifted adds sum each p
    neighbouring bytes into the first of them, which the mask keeps as the low byte of a lane."""
    if p not in _LANES or mask.shape[-1] % 8 or sys.byteorder != "little":
        _cell_sums(mask.view(np.uint8), p, np.uint8, out)
        return
    words = np.ascontiguousarray(mask).view(np.uint64)  # (B, 2, H, W/8)
    rows = np.add(words[:, :, 0::p], words[:, :, 1::p])
    for d in range(2, p):
        rows += words[:, :, d::p]
    shift = 8
    while shift < 8 * p:
        rows += rows >> np.uint64(shift)
        shift *= 2
    lane, keep = _LANES[p]
    rows &= np.uint64(keep)
    np.copyto(out, rows.view(lane))


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
