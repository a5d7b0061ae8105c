"""Worker processes that write shards in parallel, and the lock that keeps runs apart.

The parent hands shard indices to K spawned processes through a queue and gets back progress
(steps played), completions and errors; it stops them all on the first error or on Ctrl-C, and
removes the half-written ``*.partial`` files. Workers ignore SIGINT (the parent alone handles it)
and die with their parent, even under ``kill -9`` (Linux ``PR_SET_PDEATHSIG``, else a parent
check on every progress report), so a killed run never leaves writers behind.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing as mp
import os
import queue
import signal
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import PARTIAL, FolderLock, one_line

Report = Callable[[int], None]
"""Called by a job with the number of steps played since its last call."""
Job = Callable[[int, Report], Any]
"""Writes one shard: ``job(shard index, report)``, returning a picklable result; must itself be
picklable (spawned workers)."""

def _die_with_parent() -> None:
    """Linux: have the kernel kill this worker when its parent dies (e.g. ``kill -9``)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


def _worker(tasks: Any, results: Any, job: Job, out: Path, what: str, parent: int) -> None:
    """A worker process: write shards from ``tasks`` until it gets ``None``."""
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and stops us
    if os.getppid() != parent:  # it died before we could ask to die with it
        os._exit(1)

    def report(n: int) -> None:
        if os.getppid() != parent:  # orphaned where PR_SET_PDEATHSIG does not exist
            os._exit(1)
        results.put(("steps", n))

    with FolderLock(out, what, exclusive=False):
        while (i := tasks.get()) is not None:
            try:
                result = job(i, report)
            except BaseException as e:  # noqa: BLE001 - reported to the parent, which fails
                results.put(("error", i, one_line(e)))
                return
            results.put(("done", i, result))


def run_parallel(job: Job, todo: list[int], workers: int, out: Path, on_steps: Report,
                 describe: Callable[[int], str], what: str = "rollout") -> dict[int, Any]:
    """Run ``job`` for every shard in ``todo`` on ``workers`` processes writing into ``out``;
    returns each shard's result. ``what`` names the work in error messages."""
    # spawn, not forkserver: a forkserver's children are not ours, so they would outlive a
    # ``kill -9`` of this process; spawned ones are, and die with it (_die_with_parent).
    ctx = mp.get_context("spawn")
    tasks, results = ctx.Queue(), ctx.Queue()
    for i in todo:
        tasks.put(i)
    n = min(workers, len(todo))
    for _ in range(n):
        tasks.put(None)
    procs = [ctx.Process(target=_worker, args=(tasks, results, job, out, what, os.getpid()),
                         daemon=True) for _ in range(n)]
    # Workers inherit an ignored SIGINT, so that a Ctrl-C while they import cannot hit them:
    # the parent alone handles it, and stops them.
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main_thread else None
    try:
        for p in procs:
            p.start()
    finally:
        if main_thread:
            signal.signal(signal.SIGINT, previous)
    pending = set(todo)
    done: dict[int, Any] = {}
    try:
        while pending:
            try:
                msg = results.get(timeout=0.5)
            except queue.Empty:
                dead = [p for p in procs if p.exitcode not in (None, 0)]
                if dead:
                    raise Sc2DataError(f"a {what} worker died (exit code {dead[0].exitcode}); "
                                       f"rerun the same command to resume") from None
                continue
            if msg[0] == "steps":
                on_steps(msg[1])
            elif msg[0] == "done":
                pending.discard(msg[1])
                done[msg[1]] = msg[2]
            else:
                raise Sc2DataError(f"{what} of {describe(msg[1])} failed: {msg[2]}")
    finally:
        for p in procs:
            if p.is_alive() and pending:
                p.terminate()
        for p in procs:
            p.join()
        if pending:  # interrupted or failed: leave no half-written shard behind
            for stale in out.glob(f"*{PARTIAL}"):
                stale.unlink(missing_ok=True)
    return done
