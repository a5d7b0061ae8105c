"""A MEM training run's folder (``sc2data train --out RUN``), its files named once.

* ``config.json`` — the settings (:class:`~sc2data.model.train.TrainConfig`), the model's
  shape, the pair set's fingerprint and what the run used (device, threads, versions).
* ``metrics.jsonl`` — one row per finished epoch (losses and accuracies).
* ``best.pt`` / ``last.pt`` — the checkpoints of minimum validation loss and of the last epoch;
  an epoch writes them as ``*.pt.next``, records them in ``state.json``, then renames them.
* ``state.json`` — epochs done, and the sha256 of every run file of the last finished epoch.
* ``eval.json`` (``sc2data evaluate``) and ``tsne.png`` (``sc2data tsne``).

The rule for resuming a run is :mod:`sc2data.ground.resume`'s; the trainer's own part (resume
from the last finished epoch) is :func:`sc2data.model.train.prepare_run`.
"""

from __future__ import annotations

from sc2data.ground.resume import CONFIG, EVAL, STATE

__all__ = ["BEST", "CHECKPOINTS", "CONFIG", "EVAL", "LAST", "METRICS", "NEXT", "RUN_FILES",
           "STATE", "TSNE"]

METRICS = "metrics.jsonl"
BEST = "best.pt"
LAST = "last.pt"
TSNE = "tsne.png"
CHECKPOINTS = (BEST, LAST)
NEXT = ".next"
"""An epoch writes its checkpoints as ``best.pt.next`` / ``last.pt.next``, records them in
``state.json``, then renames them: a run cut anywhere in between resumes."""
RUN_FILES = (CONFIG, METRICS, *CHECKPOINTS, *(c + NEXT for c in CHECKPOINTS), STATE, EVAL, TSNE)
"""Every file a run folder may hold: what ``--overwrite`` deletes."""
