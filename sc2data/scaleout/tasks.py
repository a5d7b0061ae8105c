"""What runs inside a Ray task for :mod:`sc2data.scaleout.driver`: one shard or one label unit,
and the tracker actor the tasks report to.

Each attempt of a task registers with the tracker (where it runs), reports its progress at most
twice a second, and records why it failed before its exception goes back to Ray; the parent reads
all of it to draw the progress bar, to find hung attempts and to report retries. Before any work,
a task checks that its node has the driver's versions (the shards record them) and, for SC2, the
game.
"""

from __future__ import annotations

import os
import resource
import shutil
import socket
import time
import uuid
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import PARTIAL, fsync_path, one_line
from sc2data.ground.provenance import versions

_REPORT_EVERY_S = 0.5


class Reporter:
    """Steps or stacks done, sent to the tracker at most every half second (plus at the end)."""

    def __init__(self, tracker: Any, key: str, token: str) -> None:
        self.tracker, self.key, self.token = tracker, key, token
        self.pending, self.sent = 0, time.monotonic()

    def __call__(self, n: int) -> None:
        self.pending += n
        if time.monotonic() - self.sent >= _REPORT_EVERY_S:
            self.flush()

    def flush(self) -> None:
        self.tracker.add.remote(self.key, self.token, self.pending)
        self.pending, self.sent = 0, time.monotonic()


def _peak_rss(children: bool) -> dict[str, float]:
    """Peak resident memory (MB) of this worker and, for SC2, of its largest finished child (the
    game; short-lived forks of the worker at import time also count there, hence SC2 only)."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024 if children else 0.0
    return {"rss_mb": own, "children_rss_mb": kids}


def _attempt(tracker: Any, key: str, work: Callable[[Reporter], None],
             children: bool = False) -> dict[str, float]:
    """Run ``work`` as one attempt of task ``key``: registered with the tracker, its progress
    reported, and its failure's reason recorded before the exception goes back to Ray."""
    import ray

    token = uuid.uuid4().hex[:12]
    # Waited for: a message still in flight when the worker is killed would be lost.
    ray.get(tracker.start.remote(key, token, f"pid {os.getpid()} on {socket.gethostname()}"))
    report = Reporter(tracker, key, token)
    try:
        work(report)
    except BaseException as e:
        tracker.fail.remote(key, token, one_line(e))
        raise
    finally:
        report.flush()
    return _peak_rss(children)


def _check_node(expected: dict[str, str]) -> None:

    here = versions()
    if here != expected:
        diff = ", ".join(f"{k} {here.get(k)} (driver: {v})" for k, v in expected.items()
                         if here.get(k) != v)
        raise Sc2DataError(f"node {socket.gethostname()} has {diff}; install the same versions "
                           f"on every node")


def rollout_task(config: Any, out: str, i: int, env_factory: Any, agent_factory: Any,
                  expected: dict[str, str], tracker: Any) -> dict[str, Any]:
    """One shard, written through ``write_shard`` into an attempt folder, then moved into place;
    returns its index rows (``write_shard``'s result) and the task's peak memory."""
    from sc2data.data.dataset import shard_name
    from sc2data.data.rollout import write_shard
    from sc2data.game import env as envs

    def work(report: Reporter) -> None:
        _check_node(expected)
        if config.env == "sc2" and not envs.sc2_available():
            raise Sc2DataError(f"node {socket.gethostname()} has no StarCraft II under "
                               f"{envs.sc2_path()}; install it and set SC2PATH on every node")
        folder, name = Path(out), shard_name(i)
        attempt = folder / f"{name}.{report.token}{PARTIAL}"
        attempt.mkdir()
        try:
            rows[:] = write_shard(config=config, out=attempt, i=i, env_factory=env_factory,
                                  agent_factory=agent_factory, report=report)
            os.replace(attempt / name, folder / name)
            fsync_path(folder)
        finally:
            shutil.rmtree(attempt, ignore_errors=True)

    rows: list[dict[str, Any]] = []
    return {**_attempt(tracker, shard_name(i), work, children=config.env == "sc2"),
            "rows": rows}


def label_task(data: str, selection: tuple[Any, Any, Any], unit_key: str, part: str,
               keys: Sequence[str], batch_size: int, tracker: Any) -> dict[str, float]:
    """One label unit, checked to use the driver's rules on the driver's data."""
    from sc2data.labels.remote import label_unit

    def work(report: Reporter) -> None:
        label_unit(data, selection, unit_key, part, keys, batch_size, report)

    return _attempt(tracker, unit_key.split(":")[0], work)


class Tracker:
    """A Ray actor: each task's attempts — where they run, what they did, when last heard of."""

    def __init__(self) -> None:
        self.attempts: dict[str, list[dict[str, Any]]] = {}

    def reset(self) -> None:
        self.attempts = {}

    def start(self, key: str, token: str, where: str) -> None:
        self.attempts.setdefault(key, []).append(
            {"token": token, "where": where, "done": 0, "news": time.monotonic(), "error": None})

    def _find(self, key: str, token: str) -> dict[str, Any] | None:
        return next((a for a in self.attempts.get(key, ()) if a["token"] == token), None)

    def add(self, key: str, token: str, n: int) -> None:
        if (a := self._find(key, token)) is not None:
            a["done"] += n
            a["news"] = time.monotonic()

    def fail(self, key: str, token: str, reason: str) -> None:
        if (a := self._find(key, token)) is not None:
            a["error"] = reason

    def poll(self) -> dict[str, list[dict[str, Any]]]:
        now = time.monotonic()
        return {k: [{**a, "idle": now - a["news"]} for a in v] for k, v in self.attempts.items()}
