"""A trained MEM as a scorer: ``sc2data.load_model(RUN).distance(stacks, texts)``.

The object a reinforcement-learning loop calls every step (narration as a dense shaping reward):
batched, on CPU or GPU, with command embeddings cached (a narration repeats the same few
commands). On a GPU states go through the training path's input packing; on a CPU through
``sc2data.model.infer.FastStateEncoder``, the same function on the channels each batch uses
(distances equal to float rounding, several times faster: BENCHMARKS.md). Evaluation and t-SNE
use it too.

Either command encoder works the same way from outside: a text is encoded once, on first use, and
its embedding cached; a ``minilm`` model's checkpoint already holds the frozen sentence
embeddings of every text of its pair set, so only a never-seen text needs the sentence encoder's
package (extra ``text``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.errors import MissingDependencyError, Sc2DataError
from sc2data.schema import Schema, StackBatch


class MEMScorer:
    """A trained MEM: state and command embeddings, distances, matches."""

    def __init__(self, model: Any, meta: Mapping[str, Any], device: Any, fast: bool = True
                 ) -> None:
        from sc2data.model.infer import FastStateEncoder
        from sc2data.model.sentences import SentenceVectors
        from sc2data.model.words import WordVectors

        self.model, self.meta, self.device = model, dict(meta), device
        self.schema: Schema = model.schema
        self.threshold: float = float(meta.get("threshold", 0.5))
        self.words: WordVectors | None = None
        self.text: WordVectors | SentenceVectors
        """What turns texts into the command encoder's inputs (``.inputs(texts)``)."""
        if model.cfg.text_encoder == "lstm":
            vectors = model.command.words.weight[1:].detach().cpu().numpy()
            self.words = WordVectors(tuple(meta["words"]), vectors,
                                     str(meta.get("vectors_source")))
            self.text = self.words
        else:
            state = meta.get("sentences") or {"name": model.cfg.text_encoder, "texts": [],
                                              "embeddings": np.zeros((0, 1), np.float32)}
            self.text = SentenceVectors.from_state(state)
        self.commands: list[dict[str, Any]] = list(meta.get("commands", []))
        self._keys = model.state.keys()
        self._text_cache: dict[str, np.ndarray] = {}
        self.fast = FastStateEncoder(model.state) if fast and device.type == "cpu" and \
            FastStateEncoder.supports(model.state) else None
        """The CPU fast path, or None: the training path's packing (the reference)."""

    def __repr__(self) -> str:
        text = (f"vocab={len(self.words.words)}" if self.words is not None
                else f"text={self.model.cfg.text_encoder}")
        return (f"MEMScorer(layers={len(self.schema.layers)}, {text}, "
                f"dim={self.model.cfg.dim}, device={self.device})")

    def embed_states(self, stacks: StackBatch | Mapping[str, np.ndarray],
                     batch_size: int = 256) -> np.ndarray:
        """``(B, dim)`` float32 state embeddings of a batch of two-frame stacks."""
        import torch

        from sc2data.model.mem import model_inputs

        arrays = stacks.arrays if isinstance(stacks, StackBatch) else stacks
        missing = [k for k in self._keys if k not in arrays]
        if missing:
            raise Sc2DataError(f"the stacks lack {missing[0]!r}, which the model was trained on "
                               f"(it reads {len(self._keys)} keys, schema v{self.schema.version})")
        for l in self.schema.layers:
            size = self.schema.size(l.group)
            shape = np.shape(arrays[l.key])[1:] if l.key in self._keys else (2, size, size)
            if shape != (2, size, size):
                raise Sc2DataError(f"{l.key} has shape {shape} per stack; the model expects "
                                   f"(2, {size}, {size})")
        n = len(arrays[self._keys[0]])
        out = []
        with torch.inference_mode():
            for s in range(0, n, batch_size):
                part = {k: np.asarray(arrays[k][s:s + batch_size]) for k in self._keys}
                if self.fast is not None:
                    e = self.fast(part)
                else:
                    e = self.model.state(model_inputs(self.model, part, self.device))
                out.append(e.float().cpu().numpy())
        return np.concatenate(out) if out else np.zeros((0, self.model.cfg.dim), np.float32)

    def embed_texts(self, texts: Sequence[str]) -> np.ndarray:
        """``(T, dim)`` float32 command embeddings; each distinct text is encoded once, ever."""
        import torch

        from sc2data.model.mem import text_tensors

        new = sorted({t for t in texts if t not in self._text_cache})
        if new:
            x = text_tensors(self.text.inputs(new), self.device)
            with torch.inference_mode():
                e = self.model.command(**x).float().cpu().numpy()
            self._text_cache.update(zip(new, e))
        if not len(texts):
            return np.zeros((0, self.model.cfg.dim), np.float32)
        return np.stack([self._text_cache[t] for t in texts])

    def distance(self, stacks: StackBatch | Mapping[str, np.ndarray],
                 texts: Sequence[str] | str) -> np.ndarray:
        """``(B,)`` distances of stack i to text i (one text: to every stack)."""
        xs = self.embed_states(stacks)
        texts = [texts] if isinstance(texts, str) else list(texts)
        if len(texts) not in (1, len(xs)):
            raise Sc2DataError(f"got {len(xs)} stacks and {len(texts)} texts; pass one text per "
                               f"stack, or a single text for all")
        return np.linalg.norm(xs - self.embed_texts(texts), axis=-1)

    def distances(self, stacks: StackBatch | Mapping[str, np.ndarray],
                  texts: Sequence[str]) -> np.ndarray:
        """``(B, T)`` distances of every stack to every text."""
        return pairwise(self.embed_states(stacks), self.embed_texts(list(texts)))

    def matches(self, stacks: StackBatch | Mapping[str, np.ndarray],
                texts: Sequence[str] | str) -> np.ndarray:
        """``(B,)`` booleans: distance below the model's threshold (0.5)."""
        return self.distance(stacks, texts) < self.threshold


def pairwise(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distances between the rows of ``a`` and of ``b``: ``(len(a), len(b))``."""
    return np.linalg.norm(a[:, None, :] - b[None, :, :], axis=-1)


def load_model(run: str | os.PathLike[str], device: str = "cpu", fast: bool = True, *,
               allow_unfinished: bool = False) -> MEMScorer:
    """Load ``RUN/best.pt`` (or a checkpoint file) as a :class:`MEMScorer` on ``device``
    (``fast=False``: states through the training path's packing on a CPU too).

    A run folder is checked first: finished (unless ``allow_unfinished``) and its checkpoint the
    bytes training wrote (``state.json``)."""
    try:
        import torch  # noqa: F401
    except ImportError:
        raise MissingDependencyError("torch", "train", "sc2data.load_model") from None
    from sc2data.model.mem import load_checkpoint, resolve_device

    path = Path(run)
    if not path.exists():
        raise Sc2DataError(f"run folder {path} does not exist; pass the --out of sc2data train")
    if path.is_dir():
        from sc2data.model.train import check_run

        check_run(path, allow_unfinished=allow_unfinished)
        path = path / "best.pt"
    dev = resolve_device(device)
    model, meta = load_checkpoint(path, dev)
    if "config" not in meta and (path.parent / "config.json").is_file():
        from sc2data.model.train import read_config

        meta["config"] = read_config(path.parent)
    return MEMScorer(model, meta, dev, fast)
