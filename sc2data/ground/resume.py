"""Resume or refuse: the one rule for rerunning a command into a folder it wrote before.

Every stage that writes a folder records the settings it was given there — ``dataset.json``
(``rollout``), the labels' metadata (``label``), ``pairset.json`` (``pair``), ``config.json``
(``train``, ``rl train``). A rerun compares the settings it is given with the recorded ones
(:func:`differences`): the same settings resume the work, or find it done; other settings are
refused in one line naming what differs (:func:`refusal`), never mixed into the folder. A record
written before a setting existed reads as that setting's default (``defaults``), so the settings
may grow without refusing old folders.

Each stage keeps only its own rule on top: a dataset grows (``episodes`` may rise), labels of the
same rules whose code changed are relabelled, a pair set whose labels were remade is rebuilt (or
kept when it draws the same pairs), a training run resumes from its last finished epoch.

The record files of a run folder (MEM runs, :mod:`sc2data.model.runs`; RL runs,
:mod:`sc2data.rl.runs`) are named here, and read by :func:`read_record` with their shape checked.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.formats import Shape, check_record, loads

CONFIG = "config.json"
"""A run's settings, as it was started (MEM and RL runs)."""
STATE = "state.json"
"""A run's progress and the sha256 of the files of its last checkpoint (MEM and RL runs)."""
EVAL = "eval.json"
"""A run's evaluation (MEM and RL runs)."""


def read_record(path: Path, shape: Shape, remedy: str, *, finite: bool = True,
                defaults: Mapping[str, Any] | None = None) -> Any:
    """The JSON record at ``path``, checked to have ``shape``; a one-line error ending in
    ``remedy`` if it is unreadable or of another shape. ``defaults``: what a record written
    before a field existed reads as."""
    return read_records(path, shape, remedy, finite=finite, defaults=defaults)[0]


def read_records(path: Path, shape: Shape, remedy: str, *, lines: bool = False,
                 finite: bool = True, defaults: Mapping[str, Any] | None = None) -> list[Any]:
    """The JSON record at ``path`` (``lines``: one a line), each checked to have ``shape``."""
    try:
        text = path.read_text()
        records = [loads(t, finite=finite) for t in text.splitlines()] if lines else \
            [loads(text, finite=finite)]
    except (OSError, ValueError) as e:
        raise Sc2DataError(f"{path} is unreadable ({e}); {remedy}") from None
    if defaults:
        records = [{**defaults, **r} if isinstance(r, dict) else r for r in records]
    for r in records:
        check_record(r, shape, path, remedy)
    return records


def differences(recorded: Mapping[str, Any], given: Mapping[str, Any], *,
                keys: Iterable[str] | None = None, ignore: Iterable[str] = (),
                defaults: Mapping[str, Any] | None = None) -> list[str]:
    """The names of the settings whose ``given`` value differs from the ``recorded`` one, sorted.

    ``keys``: the names compared (default: every name either side has); ``ignore``: names that
    may differ (they change nothing but speed or where output goes); ``defaults``: what a name
    missing from ``recorded`` reads as (a setting added since the folder was written).
    """
    defaults = defaults or {}
    names = set(recorded) | set(given) if keys is None else set(keys)
    return sorted(k for k in names - set(ignore)
                  if recorded.get(k, defaults.get(k)) != given.get(k))


def refusal(folder: Path | str, holds: str, differ: Iterable[str], remedy: str) -> Sc2DataError:
    """The one-line refusal of a rerun with other settings: ``{folder} holds {holds} with other
    settings (differs in: …); {remedy}``."""
    return Sc2DataError(f"{folder} holds {holds} with other settings (differs in: "
                        f"{', '.join(differ)}); {remedy}")
