"""The mutual-embedding model (MEM): a state encoder and a command encoder into one 256-d space.

Paper, Fig. 1–2: the screen stack and the minimap stack each go through an identical
2-layer 2-d CNN, the non-spatial features through one fully-connected layer with a non-linearity;
the three are concatenated and projected to 256. A command's words are looked up in frozen
pretrained vectors, run through an LSTM and projected to 256 (``text_encoder = "lstm"``, the
paper's); or (``"minilm"``) the whole command's frozen sentence embedding
(:mod:`sc2data.model.words`, :mod:`sc2data.model.sentences`) goes through a 2-layer MLP to 256. A
state and a command match when the Euclidean distance of their embeddings is below 0.5.

Input encoding, all derived from the :class:`~sc2data.schema.Schema` the data carries:

- both frames of a stack are channels of one image (the paper's temporal stack of 2);
- a scalar layer is divided by its pysc2 scale;
- a categorical layer's ids go through a lookup table to a compact index — every id if its pysc2
  scale is at most ``max_table``, otherwise the ids seen in the training split plus one "other"
  index (``unit_type`` has 1,962 ids, BuildMarines shows a handful) — and enter one-hot
  (``onehot``, the default), through a learned ``min(embed_dim, n)``-d embedding per layer
  (``embed``), or as a number (``scalar``, index / (n − 1), the naive baseline);
- ``pool`` p = 2 (default): each p×p cell of a layer enters as the share of its pixels holding
  each id (the mean, for a scalar layer) — every pixel count survives (a new 2×2 SCV adds exactly
  one unit of "SCV"), at a quarter of the memory and convolution cost;
- the non-spatial vectors (``player`` and ``score_cumulative``) of both frames and their change,
  each as sign(x)·log1p(|x|).

Measured on the synthetic pair set (BENCHMARKS.md, "Training"): one-hot, embedded and scalar
reach the same accuracy; one-hot separated the hard pair (supply depot vs barracks) epochs before
the others in every run, and is the fastest of the two exact encodings; pooling to 32×32 changed
no figure and halved the step time.

torch is an optional dependency (extra ``train``); this module imports it, so import it lazily.
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from sc2data.ground.errors import MissingDependencyError, Sc2DataError
from sc2data.ground.files import write_atomic
from sc2data.ground.formats import CHECKPOINT
from sc2data.schema import Schema, SchemaError, StackBatch

try:
    import torch
    from torch import nn
    from torch.nn import functional as F
except ImportError as _e:  # pragma: no cover - exercised only without the extra
    raise MissingDependencyError("torch", "train", "sc2data train") from _e

THRESHOLD = 0.5
"""A state and a command match when their distance is below this (the paper's 0.5)."""


@dataclass(frozen=True)
class ModelConfig:
    """Architecture of the MEM; stored in every checkpoint."""

    categorical: Literal["embed", "onehot", "scalar"] = "onehot"
    """How categorical layers enter the CNNs (see the module docstring)."""
    embed_dim: int = 8
    """Width of a categorical layer's embedding (capped at its number of ids)."""
    max_table: int = 32
    """Categorical layers with more ids than this use a table of the ids seen in training."""
    pool: int = 2
    """Spatial layers enter as p×p cell shares (see SpatialInput); 1 = full resolution."""
    conv: tuple[tuple[int, int, int], ...] = ((16, 4, 2), (32, 3, 2))
    """(channels, kernel, stride) of the two conv layers, the same for screen and minimap; on a
    64×64 layer pooled to 32×32 they give 15×15, then 7×7 maps."""
    nonspatial: tuple[str, ...] = ("player", "score_cumulative")
    """Schema vectors fed to the non-spatial branch."""
    nonspatial_hidden: int = 64
    """Width of the non-spatial branch's fully-connected layer."""
    lstm_hidden: int = 128
    """Hidden size of the command encoder's LSTM."""
    text_encoder: Literal["lstm", "minilm"] = "lstm"
    """Command encoder: frozen word vectors → LSTM (the paper's), or a frozen sentence embedding
    → MLP."""
    text_hidden: int = 256
    """Hidden width of the MLP over a sentence embedding."""
    dim: int = 256
    """Width of the mutual embedding."""


def conv_for(pool: int, first: int = 16) -> tuple[tuple[int, int, int], ...]:
    """The two conv layers for a pool size: 15×15 then 7×7 (pooled) or 6×6 (full) maps at 64×64
    (``first``: the first one's channels)."""
    return ((first, 4, 2), (32, 3, 2)) if pool > 1 else ((first, 8, 4), (32, 4, 2))


def value_tables(schema: Schema, batches: Iterable[StackBatch], max_table: int
                 ) -> dict[str, list[int]]:
    """Per categorical layer, the ids the model distinguishes (scanning ``batches`` if needed)."""
    tables: dict[str, list[int]] = {}
    counts: dict[str, np.ndarray] = {}
    for l in schema.layers:
        if l.categorical:
            if l.scale <= max_table:
                tables[l.key] = list(range(l.scale))
            else:
                counts[l.key] = np.zeros(l.scale, np.int64)
    if counts:
        for batch in batches:
            for key, c in counts.items():
                c += np.bincount(batch.layer(key).ravel(), minlength=len(c))[:len(c)]
        tables.update({k: np.flatnonzero(c).tolist() for k, c in counts.items()})
    return tables


class SpatialInput(nn.Module):
    """One group's layers (both frames) → a float image ``(B, C, H/p, W/p)``, channels-last.

    Its input comes from :meth:`pack` (numpy, run in the loader's thread): the categorical ids
    already mapped through one concatenated table to their channel in a one-hot block, and the
    scalar layers. With ``pool`` p > 1 each p×p cell of the image holds the *share* of its pixels
    of each id (and the mean of each scalar): a 2×2 pooled one-hot keeps every pixel count (a new
    2×2 SCV still adds exactly one unit of "SCV") at a quarter of the memory and convolution cost.
    The one-hot block is filled by one ``scatter_add_`` along the last axis (``embed`` mode gets
    the same image; see :class:`EmbeddedConv`).
    """

    lut: torch.Tensor
    raw_offsets: torch.Tensor
    first: torch.Tensor
    inv_n: torch.Tensor
    inv_scale: torch.Tensor

    def __init__(self, layers: tuple, tables: Mapping[str, list[int]], cfg: ModelConfig) -> None:
        super().__init__()
        self.mode, self.pool = cfg.categorical, cfg.pool
        self.scalar_keys = [l.key for l in layers if not l.categorical]
        self.register_buffer("inv_scale", torch.tensor(
            [1.0 / l.scale for l in layers if not l.categorical]))
        cats = [l for l in layers if l.categorical]
        self.cat_keys = [l.key for l in cats]
        lut: list[np.ndarray] = []
        raw_offsets: list[int] = []
        sizes: list[int] = []
        first: list[int] = []
        for l in cats:
            values = list(tables[l.key])
            full = values == list(range(l.scale))
            n = len(values) + int(not full)  # compact index 0 is "other" unless every id is kept
            compact = np.zeros(l.scale, np.int64)
            compact[np.array(values, np.int64)] = np.arange(len(values)) + (not full)
            raw_offsets.append(sum(len(x) for x in lut))
            first.append(sum(sizes))
            lut.append(compact + first[-1])
            sizes.append(n)
        self.sizes = sizes
        small = np.uint8 if sum(sizes) <= 256 else np.int16  # one-hot channel ids, compactly
        self._lut = np.concatenate(lut).astype(small) if lut else np.zeros(0, small)
        self._raw_offsets = np.array(raw_offsets, np.int32)
        self.register_buffer("lut", torch.from_numpy(self._lut.astype(np.int64)), persistent=False)
        self.register_buffer("raw_offsets", torch.from_numpy(self._raw_offsets.astype(np.int64)),
                             persistent=False)
        self.register_buffer("first", torch.tensor(first, dtype=torch.long))
        self.register_buffer("inv_n", torch.tensor([1.0 / max(n - 1, 1) for n in sizes]))
        self.cat_width = len(sizes) if self.mode == "scalar" else sum(sizes)
        self.channels = 2 * (self.cat_width + len(self.scalar_keys))

    def pack(self, arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Stacks by key ``(B, 2, H, W)`` → ``idx`` ``(B, h, w, 2, p²·L)`` (the one-hot channel
        of each pixel of each cell; uint8 when there are ≤ 256 channels) and ``scalar`` float32
        ``(B, h, w, 2, L)`` (cell means)."""
        out: dict[str, np.ndarray] = {}
        p = self.pool
        for part, keys in (("idx", self.cat_keys), ("scalar", self.scalar_keys)):
            if not keys:
                continue
            b, t, h, w = arrays[keys[0]].shape
            if h % p or w % p:
                raise Sc2DataError(f"{keys[0]} is {h}×{w}, not divisible by the pool size {p}")
            cells = [(dy, dx) for dy in range(p) for dx in range(p)]
            if part == "idx":  # (B, h, w, 2, p·p·L): the one-hot channels of a cell's pixels
                a = np.empty((b, h // p, w // p, t, len(cells), len(keys)), self._lut.dtype)
                for i, k in enumerate(keys):
                    ch = self._lut[self._raw_offsets[i]:][arrays[k]]
                    for j, (dy, dx) in enumerate(cells):
                        a[..., j, i] = ch[:, :, dy::p, dx::p].transpose(0, 2, 3, 1)
                out[part] = a.reshape(b, h // p, w // p, t, -1)
            else:  # (B, h, w, 2, L): cell means
                a = np.empty((b, h // p, w // p, t, len(keys)), np.float32)
                for i, k in enumerate(keys):
                    x = arrays[k]
                    cell = x[:, :, ::p, ::p].astype(np.float32)
                    for dy, dx in cells[1:]:
                        cell += x[:, :, dy::p, dx::p]
                    a[..., i] = cell.transpose(0, 2, 3, 1) * (1.0 / p ** 2)
                out[part] = a
        return out

    def pack_torch(self, arrays: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """:meth:`pack` in torch, for a GPU: raw stacks go to the device, packing runs there."""
        out: dict[str, torch.Tensor] = {}
        p = self.pool
        for part, keys in (("idx", self.cat_keys), ("scalar", self.scalar_keys)):
            if not keys:
                continue
            x = torch.stack([arrays[k] for k in keys], -1)  # (B, 2, H, W, L)
            b, t, h, w, n = x.shape
            if h % p or w % p:
                raise Sc2DataError(f"{keys[0]} is {h}×{w}, not divisible by the pool size {p}")
            if part == "idx":
                x = self.lut[x.long() + self.raw_offsets].view(b, t, h // p, p, w // p, p, n)
                out[part] = x.permute(0, 2, 4, 1, 3, 5, 6).reshape(b, h // p, w // p, t, -1)
            else:
                x = x.float().view(b, t, h // p, p, w // p, p, n).sum((3, 5)) * (1.0 / p ** 2)
                out[part] = x.permute(0, 2, 3, 1, 4)
        return out

    def forward(self, idx: torch.Tensor | None, scalar: torch.Tensor | None) -> torch.Tensor:
        ref = idx if idx is not None else scalar
        assert ref is not None
        b, h, w, t, _ = ref.shape
        n_s = len(self.scalar_keys)
        out = torch.zeros(b, h, w, t, n_s + self.cat_width, device=ref.device)
        if scalar is not None:
            out[..., :n_s] = scalar * self.inv_scale
        if idx is not None:
            idx = idx.long()
            share = torch.full((), 1.0 / self.pool ** 2, device=ref.device).expand(idx.shape)
            if self.mode == "scalar":  # mean compact index / (n - 1) over the cell's pixels
                v = (idx.view(b, h, w, t, -1, len(self.sizes)) - self.first).float() * self.inv_n
                out[..., n_s:] = v.mean(-2)
            else:  # onehot, and embed (whose embedding lives in the first convolution)
                out[..., n_s:].scatter_add_(-1, idx, share)
        return out.view(b, h, w, -1).permute(0, 3, 1, 2)  # (B, C, h, w), channels-last strides


class EmbeddedConv(nn.Module):
    """The first convolution of an ``embed`` tower: ``conv(W, embed(x))`` computed as
    ``conv(W·E, x)`` on the one-hot image ``x``.

    Each categorical layer has its own embedding ``E_l`` (``n_l × min(embed_dim, n_l)``); scalar
    channels pass through. Embedding and convolution are both linear, so folding the
    block-diagonal ``E`` into the kernel is the same function as embedding every pixel first — at
    the cost of the one-hot convolution, instead of a per-pixel lookup whose index-add backward
    is 3× slower on CPU (measured).
    """

    def __init__(self, n_scalar: int, sizes: list[int], embed_dim: int, c_out: int, k: int,
                 s: int) -> None:
        super().__init__()
        self.n_scalar = n_scalar
        dims = [min(embed_dim, n) for n in sizes]
        # std 1/√d: an embedded pixel has about the norm of its one-hot vector
        self.embeds = nn.ParameterList([nn.Parameter(torch.randn(n, d) / d ** 0.5)
                                        for n, d in zip(sizes, dims)])
        self.conv = nn.Conv2d(2 * (n_scalar + sum(dims)), c_out, k, s)

    def mixing(self) -> torch.Tensor:
        """``(2·(scalars + one-hot), 2·(scalars + embedded))``: both frames, block-diagonal."""
        frame = torch.block_diag(torch.eye(self.n_scalar, device=self.conv.weight.device),
                                 *self.embeds)
        return torch.block_diag(frame, frame)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        w = torch.einsum("odyx,cd->ocyx", self.conv.weight, self.mixing())
        return F.conv2d(x, w, self.conv.bias, self.conv.stride)


class StateEncoder(nn.Module):
    """Screen CNN ‖ minimap CNN ‖ non-spatial FC → FC → ``dim``."""

    def __init__(self, schema: Schema, tables: Mapping[str, list[int]], cfg: ModelConfig) -> None:
        super().__init__()
        self.inputs = nn.ModuleDict()
        self.groups: list[tuple[str, SpatialInput]] = []  # the same modules, typed, in order
        self.towers = nn.ModuleDict()
        width = 0
        for group in ("screen", "minimap"):
            layers = schema.group(group)
            if not layers:
                continue
            inp = SpatialInput(layers, tables, cfg)
            convs: list[nn.Module] = []
            c_in = inp.channels
            for i, (c_out, k, s) in enumerate(cfg.conv):
                if i == 0 and cfg.categorical == "embed" and inp.sizes:
                    convs += [EmbeddedConv(len(inp.scalar_keys), inp.sizes, cfg.embed_dim,
                                           c_out, k, s), nn.ReLU()]
                else:
                    convs += [nn.Conv2d(c_in, c_out, k, s), nn.ReLU()]
                c_in = c_out
            tower = nn.Sequential(*convs, nn.Flatten())
            size = schema.size(group) // cfg.pool
            with torch.no_grad():
                width += tower(torch.zeros(1, inp.channels, size, size)).shape[1]
            self.inputs[group], self.towers[group] = inp, tower
            self.groups.append((group, inp))
        names = {v.name: v for v in schema.vectors}
        missing = [n for n in cfg.nonspatial if n not in names]
        if missing:
            raise Sc2DataError(f"the data has no non-spatial vector {missing[0]!r}")
        self.vectors = list(cfg.nonspatial)
        n_fields = sum(names[n].size for n in self.vectors)
        self.nonspatial = nn.Sequential(nn.Linear(3 * n_fields, cfg.nonspatial_hidden), nn.ReLU()) \
            if n_fields else None
        width += cfg.nonspatial_hidden if n_fields else 0
        self.head = nn.Linear(width, cfg.dim)

    def forward(self, x: Mapping[str, torch.Tensor]) -> torch.Tensor:
        feats = [self.towers[g](inp(x.get(f"{g}.idx"), x.get(f"{g}.scalar")))
                 for g, inp in self.groups]
        if self.nonspatial is not None:  # both frames and their change, sign(x)·log1p(|x|)
            v = x["vectors"]
            v = torch.cat([v[:, 0], v[:, 1], v[:, 1] - v[:, 0]], -1)
            feats.append(self.nonspatial(torch.sign(v) * torch.log1p(v.abs())))
        return self.head(torch.cat(feats, 1))

    def keys(self) -> list[str]:
        """The schema keys this encoder reads."""
        return [k for _, g in self.groups for k in g.scalar_keys + g.cat_keys] + self.vectors

    def pack(self, arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Stacks by schema key (``(B, 2, …)``) → this encoder's inputs, in numpy on the CPU.

        Runs in the loader's thread, off the training loop; see :meth:`SpatialInput.pack`. The
        non-spatial vectors are concatenated, float32 ``(B, 2, F)``.
        """
        out: dict[str, np.ndarray] = {}
        for g, inp in self.groups:
            out.update({f"{g}.{k}": a for k, a in inp.pack(arrays).items()})
        if self.vectors:
            out["vectors"] = np.concatenate([arrays[n] for n in self.vectors], -1).astype(
                np.float32)
        return out

    def pack_torch(self, arrays: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """:meth:`pack` for raw stack tensors already on a GPU (see :func:`model_inputs`)."""
        out: dict[str, torch.Tensor] = {}
        for g, inp in self.groups:
            out.update({f"{g}.{k}": a for k, a in inp.pack_torch(arrays).items()})
        if self.vectors:
            out["vectors"] = torch.cat([arrays[n] for n in self.vectors], -1).float()
        return out


class CommandEncoder(nn.Module):
    """Frozen word vectors → LSTM → FC → ``dim``. Token id 0 is padding."""

    def __init__(self, vectors: np.ndarray, cfg: ModelConfig) -> None:
        super().__init__()
        table = torch.cat([torch.zeros(1, vectors.shape[1]), torch.as_tensor(vectors)])
        self.words = nn.Embedding.from_pretrained(table, freeze=True, padding_idx=0)
        self.lstm = nn.LSTM(vectors.shape[1], cfg.lstm_hidden, batch_first=True)
        self.head = nn.Linear(cfg.lstm_hidden, cfg.dim)

    def forward(self, ids: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        packed = nn.utils.rnn.pack_padded_sequence(self.words(ids), lengths.cpu(),
                                                   batch_first=True, enforce_sorted=False)
        _, (h, _) = self.lstm(packed)
        return self.head(h[-1])


class SentenceCommandEncoder(nn.Module):
    """A frozen sentence embedding (computed once per text, outside) → Linear–ReLU–Linear →
    ``dim``: the only trained part of the ``minilm`` command encoder."""

    def __init__(self, text_dim: int, cfg: ModelConfig) -> None:
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(text_dim, cfg.text_hidden), nn.ReLU(),
                                 nn.Linear(cfg.text_hidden, cfg.dim))

    def forward(self, emb: torch.Tensor) -> torch.Tensor:
        return self.mlp(emb.float())


class MEM(nn.Module):
    """The mutual-embedding model: ``distance(state, command)``; match ⇔ distance < threshold.

    ``vectors`` are the LSTM's word vectors; the ``minilm`` encoder takes ``text_dim`` instead
    (the sentence embedding's width).
    """

    def __init__(self, schema: Schema, tables: Mapping[str, list[int]],
                 vectors: np.ndarray | None, cfg: ModelConfig, text_dim: int = 0) -> None:
        super().__init__()
        self.schema, self.tables, self.cfg = schema, dict(tables), cfg
        self.state = StateEncoder(schema, tables, cfg)
        self.command: nn.Module
        if cfg.text_encoder == "lstm":
            if vectors is None:
                raise ValueError("the lstm command encoder needs word vectors")
            self.command = CommandEncoder(vectors, cfg)
        elif cfg.text_encoder == "minilm":
            if text_dim < 1:
                raise ValueError("a sentence command encoder needs text_dim")
            self.command = SentenceCommandEncoder(text_dim, cfg)
        else:
            raise Sc2DataError(f"unknown text encoder {cfg.text_encoder!r}; use lstm or minilm")

    def forward(self, x: Mapping[str, torch.Tensor], text: Mapping[str, torch.Tensor],
                which: torch.Tensor) -> torch.Tensor:
        """Distances of B packed states to texts ``which`` (indices into the T texts whose
        encoder inputs are ``text``: see :func:`text_tensors`)."""
        return distance(self.state(x), self.command(**text)[which])

    def l2(self) -> torch.Tensor:
        """Σ w² over trainable weight tensors (kernels, matrices, embeddings; no biases)."""
        return sum((p.float() ** 2).sum() for p in self.parameters()
                   if p.requires_grad and p.dim() > 1)  # type: ignore[return-value]


def distance(xs: torch.Tensor, xc: torch.Tensor) -> torch.Tensor:
    """Euclidean distance per row; the epsilon keeps the gradient finite at 0."""
    return torch.sqrt(((xs.float() - xc.float()) ** 2).sum(-1) + 1e-12)


def to_tensors(arrays: Mapping[str, np.ndarray], pin: bool = False) -> dict[str, torch.Tensor]:
    """numpy arrays → CPU tensors, pinned for fast asynchronous copies to a GPU if ``pin``.

    uint16 layers are viewed as int16 (no copy: every pysc2 scale is below 2¹⁵)."""
    out = {k: torch.from_numpy(a.view(np.int16) if a.dtype == np.uint16 else a)
           for k, a in arrays.items()}
    return {k: t.pin_memory() for k, t in out.items()} if pin else out


def to_device(tensors: Mapping[str, torch.Tensor], device: torch.device
              ) -> dict[str, torch.Tensor]:
    return {k: t.to(device, non_blocking=True) for k, t in tensors.items()}


def model_inputs(model: MEM, arrays: Mapping[str, np.ndarray], device: torch.device
                 ) -> dict[str, torch.Tensor]:
    """Raw stacks (numpy, by schema key) → the state encoder's inputs on ``device``: packed in
    numpy on a CPU, in torch on a GPU."""
    if device.type == "cpu":
        return to_tensors(model.state.pack(arrays))
    raw = to_device(to_tensors({k: np.ascontiguousarray(arrays[k])
                                for k in model.state.keys()}), device)
    return model.state.pack_torch(raw)


def text_tensors(inputs: Mapping[str, np.ndarray], device: torch.device
                 ) -> dict[str, torch.Tensor]:
    """A text encoder's numpy inputs (``WordVectors.inputs``, ``SentenceVectors.inputs``) as
    tensors on ``device``; an LSTM's ``lengths`` stay on the CPU, where packing wants them."""
    return {k: torch.from_numpy(v) if k == "lengths" else torch.from_numpy(v).to(device)
            for k, v in inputs.items()}


def save_checkpoint(path: str | os.PathLike[str], model: MEM, words: tuple[str, ...],
                    extra: Mapping[str, Any]) -> None:
    """Write model state, schema, tables, vocabulary and ``extra`` (config, …), atomically."""
    path = Path(path)
    blob = {**CHECKPOINT.header(),
            "schema": model.schema.to_dict(), "model_config": asdict(model.cfg),
            "tables": model.tables, "words": list(words),
            "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
            **extra}
    save_atomic(blob, path)


def save_atomic(obj: Any, path: Path) -> None:
    """``torch.save`` ``obj`` to ``path`` atomically. It is serialised in memory first: torch's
    writer turns a full disk into an opaque RuntimeError, a plain write into ENOSPC."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    write_atomic(path, buf.getvalue())


def load_checkpoint(path: str | os.PathLike[str], device: str | torch.device = "cpu"
                    ) -> tuple[MEM, dict[str, Any]]:
    """Rebuild a MEM from ``best.pt``; refuses other formats and other schema versions."""
    path = Path(path)
    if not path.is_file():
        raise Sc2DataError(f"{path} does not exist; train a model first (sc2data train)")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:
        raise Sc2DataError(f"{path} is not a readable checkpoint ({type(e).__name__})") from None
    CHECKPOINT.check(blob, path)
    try:
        schema = Schema.from_dict(blob["schema"])
    except SchemaError as e:
        raise Sc2DataError(f"{path}: the model's {e}") from None
    mc = dict(blob["model_config"])
    mc["conv"] = tuple(tuple(c) for c in mc["conv"])
    mc["nonspatial"] = tuple(mc["nonspatial"])
    cfg = ModelConfig(**mc)
    sd = blob["state_dict"]
    if cfg.text_encoder == "lstm":
        dim = sd["command.words.weight"].shape[1]
        model = MEM(schema, blob["tables"], np.zeros((len(blob["words"]), dim), np.float32), cfg)
    else:
        model = MEM(schema, blob["tables"], None, cfg, text_dim=sd["command.mlp.0.weight"].shape[1])
    model.load_state_dict(flush_denormals(sd))
    return model.to(device).eval(), blob


def flush_denormals(state: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """``state`` with float32's denormal values set to zero. Training's weight penalty leaves
    many weights there (12 % of a 20-epoch MEM's), where a CPU computes ~100× slower; their
    contribution to a distance is below 1e-38, so nothing measurable changes."""
    tiny = torch.finfo(torch.float32).tiny
    return {k: v.masked_fill(v.abs() < tiny, 0.0) if v.is_floating_point() else v
            for k, v in state.items()}


def resolve_device(name: str) -> torch.device:
    """``auto`` → cuda if available, else cpu; ``cuda`` without a GPU is an error."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise Sc2DataError("--device cuda: no CUDA GPU is visible to torch; use --device cpu")
    if name not in ("cpu",) and not name.startswith("cuda"):
        raise Sc2DataError(f"unknown device {name!r}; use auto, cpu or cuda")
    return torch.device(name)


__all__ = ["MEM", "ModelConfig", "conv_for", "distance", "flush_denormals", "load_checkpoint",
           "model_inputs", "resolve_device", "save_checkpoint", "text_tensors", "to_device",
           "to_tensors", "value_tables"]
