"""Labelling units away from the process that runs :func:`sc2data.labels.label.label`: in local
worker processes (:class:`LocalUnits`, ``--workers K``) or in Ray tasks (through
:func:`label_unit`). Each loads the rules itself and checks they are the run's."""

from __future__ import annotations

import functools
import socket
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import PARTIAL
from sc2data.ground.progress import Bar
from sc2data.ground.resume import STATE
from sc2data.ground.workers import run_parallel
from sc2data.labels.apply import labels_fingerprint_for, parts_run, write_part
from sc2data.labels.registry import Registered, load_registry
from sc2data.labels.source import Source, WorkUnit, dataset_source

Selection = tuple[tuple[str, ...] | None, tuple[str, ...], str | None]
"""``(include, exclude, rules_dir)``: how a process re-selects the run's rules."""

@functools.lru_cache(maxsize=4)
def _rules_and_source(data: str, selection: Selection, run: str
                      ) -> tuple[Sequence[Registered], Source]:
    """Loaded once per worker process and run (``run``: the run's labels fingerprint, so a process
    that outlives a run, as Ray's do, reloads for the next)."""
    include, exclude, rules_dir = selection
    return load_registry(rules_dir).select(include, exclude), dataset_source(data)


def label_unit(data: str, selection: Selection, unit_key: str, part: str,
               keys: Sequence[str], batch_size: int, report: Callable[[int], None]) -> None:
    """Label unit ``unit_key`` of the dataset at ``data`` into ``part``, away from the process
    that runs :func:`label` (a worker process, a Ray task): the rules are loaded from
    ``selection`` = (include, exclude, rules_dir) and checked to be the run's (its parts
    folder's ``state.json``), then the unit is written with :func:`write_part`."""
    include, exclude, rules_dir = selection
    run = str(parts_run(Path(part).parent / STATE))
    rules, source = _rules_and_source(data, (None if include is None else tuple(include),
                                             tuple(exclude), rules_dir), run)
    if labels_fingerprint_for(rules, source.info) != run:
        raise Sc2DataError(f"{socket.gethostname()} sees other rules or other data than the run "
                           f"that started this label; install the same sc2data and rule "
                           f"plugins on every node and share the dataset folder")
    unit = next(u for u in source.units if u.key == unit_key)
    write_part(unit, rules, keys, batch_size, Path(part), on_batch=report)


def _unit_job(data: str, selection: Selection, units: Sequence[tuple[str, str]],
              keys: Sequence[str], batch_size: int, i: int, report: Callable[[int], None]
              ) -> None:
    label_unit(data, selection, units[i][0], units[i][1], keys, batch_size, report)


@dataclass(frozen=True)
class LocalUnits:
    """A unit runner: label units in ``workers`` local processes (as rollout's workers run)."""

    workers: int
    data: Path
    selection: Selection

    def __call__(self, todo: Sequence[tuple[WorkUnit, Path]], keys: Sequence[str], batch_size: int,
                 bar: Bar) -> None:

        if not todo:
            return
        units = [(unit.key, str(path)) for unit, path in todo]
        job = functools.partial(_unit_job, str(Path(self.data).resolve()), self.selection, units,
                                tuple(keys), batch_size)
        parts = todo[0][1].parent
        try:
            run_parallel(job, list(range(len(units))), self.workers, parts, bar.update,
                         lambda i: units[i][0].split(":")[0], what="label")
        except BaseException:  # a worker stopped mid-write leaves its temporary part behind
            for stale in parts.glob(f"*{PARTIAL}"):
                stale.unlink(missing_ok=True)
            raise
