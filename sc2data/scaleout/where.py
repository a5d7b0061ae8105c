"""Where rollout and label run: local worker processes, or Ray tasks — chosen here, once.

``sc2data rollout``, ``sc2data label`` and ``sc2data build`` hand their ``--ray`` settings
(:class:`~sc2data.scaleout.driver.RayOptions`, or None without ``--ray``) to :func:`run_rollout`
and :func:`run_label`; the data does not depend on the choice. Ray is imported only with ``--ray``.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sc2data.data.rollout import RolloutConfig, RolloutSummary, check_folder, rollout
from sc2data.labels.label import LabelSummary, label_dataset

if TYPE_CHECKING:
    from sc2data.scaleout.driver import RayOptions


@contextlib.contextmanager
def session(ray: RayOptions | None, config: RolloutConfig | None = None,
            out: str | os.PathLike[str] | None = None) -> Iterator[None]:
    """Ray connected for the duration with ``ray`` (several stages on one instance), after
    ``config`` and the folder ``out`` check out (Ray does not start for nothing); nothing
    without ``ray``."""
    if ray is None:
        yield
        return
    from sc2data.scaleout.driver import connect

    if config is not None and out is not None:
        config.validate()
        check_folder(config, Path(out))
    with connect(ray):
        yield


def run_rollout(config: RolloutConfig, out: str | os.PathLike[str], *, workers: int,
             progress: bool | None, ray: RayOptions | None) -> tuple[RolloutSummary, list[str]]:
    """Roll ``config`` out into ``out``: in ``workers`` local processes, or as Ray tasks with
    ``ray``. Returns the summary and the Ray report's lines (none locally)."""
    if ray is None:
        return rollout(config, out, workers=workers, progress=progress), []
    from sc2data.scaleout.driver import rollout_on_ray

    summary, report = rollout_on_ray(config, out, ray, progress=progress)
    return summary, report.lines() if report.tasks else []


def run_label(data: str | os.PathLike[str], *, workers: int, ray: RayOptions | None,
          **selection: Any) -> tuple[LabelSummary, list[str]]:
    """Label the dataset ``data`` (``selection``: :func:`~sc2data.labels.label.label_dataset`'s
    rules and settings): in ``workers`` local processes, or as Ray tasks with ``ray``. Returns the
    summary and the Ray report's lines (none locally)."""
    if ray is None:
        return label_dataset(data, workers=workers, **selection), []
    from sc2data.scaleout.driver import label_on_ray

    summary, report = label_on_ray(data, ray, **selection)
    return summary, report.lines() if report.tasks else []
