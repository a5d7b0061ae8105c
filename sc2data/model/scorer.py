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

On a CPU each call runs on ``threads`` torch threads (one by default) and gives the process's
own setting back after: a reward call is small (a batch of a few stacks), and there more threads
only cost: at batch 1 on this project's busy 2-core machine, a median 68 ms a call on both
threads against 11 ms on one (setting the threads and back costs ~0.3 ms of that).
``threads=None`` leaves torch's setting as it is (``torch.set_num_threads``).

What comes in is checked as the CLI checks it: a checkpoint by content when it loads (see
:func:`load_model`), and the stacks on every call — every key the model reads, with the shape and
an integer dtype per layer, ids within each layer's range, and finite vectors — so that a bad input
is a :class:`~sc2data.ground.errors.Sc2DataError` naming it, never a NaN or silently wrong distance.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.ground.errors import MissingDependencyError, Sc2DataError
from sc2data.model.runs import BEST, CHECKPOINTS, CONFIG, STATE
from sc2data.schema import Schema, StackBatch


class MEMScorer:
    """A trained MEM: state and command embeddings, distances, matches."""

    def __init__(self, model: Any, meta: Mapping[str, Any], device: Any, fast: bool = True,
                 threads: int | None = 1) -> None:
        from sc2data.model.infer import FastStateEncoder
        from sc2data.model.sentences import SentenceVectors
        from sc2data.model.words import WordVectors

        self.model, self.meta, self.device = model, dict(meta), device
        self.threads: int | None = check_threads(threads) if device.type == "cpu" else None
        """Torch threads each call runs on (a CPU model), or None: torch's own setting."""
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

        arrays = self._checked(stacks.arrays if isinstance(stacks, StackBatch) else stacks)
        n = len(arrays[self._keys[0]])
        out = []
        with torch.inference_mode(), torch_threads(self.threads):
            for s in range(0, n, batch_size):
                part = {k: np.asarray(arrays[k][s:s + batch_size]) for k in self._keys}
                if self.fast is not None:
                    e = self.fast(part)
                else:
                    e = self.model.state(model_inputs(self.model, part, self.device))
                out.append(e.float().cpu().numpy())
        return np.concatenate(out) if out else np.zeros((0, self.model.cfg.dim), np.float32)

    def _checked(self, arrays: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """The arrays the model reads, as numpy (a layer's ids in its stored dtype); a one-line
        error naming the first key that is missing, of another shape or batch size, not integer
        ids (a layer) or numbers (a vector), an id outside its layer's range, or a vector holding
        NaN or infinity."""
        missing = [k for k in self._keys if k not in arrays]
        if missing:
            raise Sc2DataError(f"the stacks lack {missing[0]!r}, which the model was trained on "
                               f"(it reads {len(self._keys)} keys, schema v{self.schema.version})")
        out = {k: np.asarray(arrays[k]) for k in self._keys}
        sizes = {k: len(a) if a.ndim else 0 for k, a in out.items()}
        first = self._keys[0]
        odd = next((k for k in sizes if sizes[k] != sizes[first]), None)
        if odd is not None:
            raise Sc2DataError(f"the stacks' keys disagree on the batch size ({first}: "
                               f"{sizes[first]}, {odd}: {sizes[odd]})")
        for l in self.schema.layers:
            if l.key not in out:
                continue
            a, size = out[l.key], self.schema.size(l.group)
            if a.shape[1:] != (2, size, size) or a.ndim != 4:
                raise Sc2DataError(f"{l.key} has shape {a.shape[1:]} per stack; the model expects "
                                   f"(2, {size}, {size})")
            if a.dtype.kind not in "ui":
                raise Sc2DataError(f"{l.key} holds {a.dtype} values; the model reads integer ids "
                                   f"({l.dtype}, as sc2data.Stacker and open_dataset give them)")
            top = l.scale if l.categorical else l.limit  # a categorical id indexes a table
            if a.size and (a.dtype != l.dtype or top < l.limit):  # its own dtype: in range
                lo, hi = 0 if a.dtype.kind == "u" else int(a.min()), int(a.max())
                if lo < 0 or hi >= top:
                    raise Sc2DataError(f"{l.key} holds {lo if lo < 0 else hi}, outside the "
                                       f"layer's range [0, {top}); pass the layer as observed")
                out[l.key] = a.astype(l.dtype, copy=False)  # in range: lossless
        for v in self.schema.vectors:
            if v.name not in out:
                continue
            a = out[v.name]
            if a.shape[1:] != (2, v.size) or a.ndim != 3:
                raise Sc2DataError(f"{v.name} has shape {a.shape[1:]} per stack; the model "
                                   f"expects (2, {v.size})")
            if a.dtype.kind not in "uif":
                raise Sc2DataError(f"{v.name} holds {a.dtype} values; the model reads numbers "
                                   f"({v.dtype}, as sc2data.Stacker gives them)")
            if a.dtype.kind == "f" and not np.isfinite(a).all():
                bad = np.argwhere(~np.isfinite(a))[0]
                raise Sc2DataError(f"{v.name} holds {a[tuple(bad)]} (stack {bad[0]}, field "
                                   f"{v.fields[bad[2]]!r}); the model reads finite numbers")
        return out

    def embed_texts(self, texts: Sequence[str]) -> np.ndarray:
        """``(T, dim)`` float32 command embeddings; each distinct text is encoded once, ever."""
        import torch

        from sc2data.model.mem import text_tensors

        new = sorted({t for t in texts if t not in self._text_cache})
        if new:
            x = text_tensors(self.text.inputs(new), self.device)
            with torch.inference_mode(), torch_threads(self.threads):
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


def check_threads(threads: int | None) -> int | None:
    """``threads`` if it is None or a positive count; a one-line error otherwise."""
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int)
                                or threads < 1):
        raise Sc2DataError(f"threads must be a positive number of torch threads or None (torch's "
                           f"own setting), not {threads!r}")
    return threads


@contextlib.contextmanager
def torch_threads(threads: int | None) -> Iterator[None]:
    """Run the block on ``threads`` torch threads, then give the process its setting back."""
    if threads is None:
        yield
        return
    import torch

    before = torch.get_num_threads()
    if before == threads:
        yield
        return
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def pairwise(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distances between the rows of ``a`` and of ``b``: ``(len(a), len(b))``."""
    return np.linalg.norm(a[:, None, :] - b[None, :, :], axis=-1)


def load_model(run: str | os.PathLike[str], device: str = "cpu", fast: bool = True, *,
               threads: int | None = 1, allow_unfinished: bool = False) -> MEMScorer:
    """Load ``RUN/best.pt`` (or a checkpoint file) as a :class:`MEMScorer` on ``device``
    (``fast=False``: states through the training path's packing on a CPU too; ``threads``: torch
    threads per call on a CPU, None for torch's own setting).

    Checked first, by content: a run folder, or a checkpoint file in one (beside a
    ``state.json`` that records it), is a finished run (unless ``allow_unfinished``) whose
    checkpoint is the bytes training wrote (sha256 in ``state.json``). A checkpoint file outside
    a run has no recorded sha256: every record of its archive must pass its CRC-32 (one flipped
    bit fails it). Either way the file must load as an sc2data model checkpoint of this schema
    version, and every weight must be finite."""
    try:
        import torch  # noqa: F401
    except ImportError:
        raise MissingDependencyError("torch", "train", "sc2data.load_model") from None
    from sc2data.model.mem import load_checkpoint, resolve_device

    check_threads(threads)
    path = Path(run)
    if not path.exists():
        raise Sc2DataError(f"run folder {path} does not exist; pass the --out of sc2data train")
    if path.is_dir():
        from sc2data.model.train import check_run

        check_run(path, allow_unfinished=allow_unfinished)
        path = path / BEST
    else:
        _check_file(path, allow_unfinished)
    dev = resolve_device(device)
    model, meta = load_checkpoint(path, dev)
    _check_finite(model, path)
    if "config" not in meta and (path.parent / CONFIG).is_file():
        from sc2data.model.train import read_config

        meta["config"] = read_config(path.parent)
    return MEMScorer(model, meta, dev, fast, threads)


def _check_file(path: Path, allow_unfinished: bool) -> None:
    """A checkpoint file by content: against its run's ``state.json`` where one records it (or
    should: ``best.pt``, ``last.pt``), else every record of its archive through its CRC-32."""
    import zipfile

    from sc2data.model.train import check_run, read_state

    state = read_state(path.parent) if (path.parent / STATE).is_file() else None
    if state is not None and (path.name in state["sha256"] or path.name in CHECKPOINTS):
        check_run(path.parent, allow_unfinished=allow_unfinished, files=(path.name,))
        return
    if not zipfile.is_zipfile(path):
        return  # not torch's archive: load_checkpoint says so
    try:
        with zipfile.ZipFile(path) as archive:
            bad = archive.testzip()
    except (OSError, zipfile.BadZipFile, EOFError) as e:
        raise Sc2DataError(f"{path} is not a readable checkpoint ({type(e).__name__}: {e}); "
                           f"use an intact copy, or train again") from None
    if bad is not None:
        raise Sc2DataError(f"{path} is damaged: its record {bad} fails its CRC-32 check; use an "
                           f"intact copy, or train again")


def _check_finite(model: Any, path: Path) -> None:
    """One-line error unless every weight of ``model`` is finite."""
    import torch

    bad = [k for k, v in model.state_dict().items()
           if v.is_floating_point() and not bool(torch.isfinite(v).all())]
    if bad:
        more = f" and {len(bad) - 1} more" if len(bad) > 1 else ""
        raise Sc2DataError(f"{path} holds non-finite weights ({bad[0]}{more}): damaged, or its "
                           f"training diverged; use an intact copy, or train again")
