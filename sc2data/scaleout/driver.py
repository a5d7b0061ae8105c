"""Rollout shards and label units as Ray tasks, on a local Ray instance or an existing cluster.

One task is one shard (its episodes, one simulator or SC2 instance at a time) or one label unit,
asking Ray for one CPU and a memory budget. A rollout task writes through the same
:func:`sc2data.data.rollout.write_shard` as a local run, but into a folder of its own attempt,
``shard-NNNNN.h5.<token>.partial/`` inside the dataset folder, and moves the complete shard into
place (one rename on the same file system). So a killed, hung or abandoned attempt never leaves
anything that looks complete, two attempts never write the same file, and the usual cleanup of a
rerun (``*.partial``) removes the debris. A label task writes its unit's part atomically, as a
local run does. The parent shows the usual progress bar, fed by a small actor the tasks report
to, and writes the index (or combines the label parts) at the end.

Faults, with a budget of ``retries`` extra attempts per task:

* the worker process dies (killed, out of memory, node lost): Ray retries it (``max_retries``);
* the game instance crashes (pysc2's connection or launch errors, :func:`transient_errors`):
  Ray retries it (``retry_exceptions``);
* it hangs — no progress for ``timeout_s`` — the parent cancels it (``ray.cancel(force=True)``
  kills the worker) and submits it again with what is left of the budget.

Any other exception (a bug, a bad setting) fails the run at once, as a local run does. Past the
budget, the run fails with one line naming the task; rerunning the same command resumes. A run
ends with :class:`ScaleoutReport`: which tasks were retried, why, and each attempt's outcome.
What runs inside the tasks is in :mod:`sc2data.scaleout.tasks`.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sc2data.ground.errors import MissingDependencyError, Sc2DataError
from sc2data.ground.files import PARTIAL, one_line
from sc2data.ground.progress import Bar
from sc2data.ground.provenance import versions
from sc2data.scaleout.tasks import Tracker, label_task, rollout_task

if TYPE_CHECKING:  # types only: the stages import this module, not the other way round
    from sc2data.data.rollout import AgentFactory, EnvFactory, RolloutConfig, RolloutSummary
    from sc2data.labels.label import LabelSummary
    from sc2data.labels.remote import Selection
    from sc2data.labels.source import WorkUnit

DEFAULT_RETRIES = 2
"""Extra attempts per task after a worker death, a crashed instance or a hang."""
DEFAULT_TIMEOUT_S = 600.0
"""Seconds a task may go without reporting progress before it counts as hung. SC2 takes
10–60 s to launch and tasks report every 200 steps, so minutes are safe."""
TASK_MEMORY_MB = {"sim": 512, "sc2": 2048}
"""Memory requested per rollout task: a simulator task peaks near 300 MB (docs/ray.md), an SC2
instance takes 1–2 GB besides its worker."""
LABEL_MEMORY_MB = 1024
"""Memory requested per label task (a read of 4,096 stacks of the keys the rules need)."""
LOCAL_OBJECT_STORE = 200 << 20
"""Object store of a local instance: tasks return only small summaries."""
SUBREAPER = "RAY_kill_child_processes_on_worker_exit_with_raylet_subreaper"
"""Ray setting: the raylet kills what a dead worker started (its SC2 instance), within 10 s."""
POLL_S = 0.5
"""How often the parent looks at the tasks (progress bar, hang check)."""
_ADDRESS = re.compile(r"local|auto|ray://\S+|[\w.\-]+:\d+")


def require_ray() -> Any:
    """The ``ray`` module, or a one-line error saying how to install it."""
    try:
        import ray
    except ImportError:
        raise MissingDependencyError("ray", "ray", "--ray") from None
    return ray


def is_address(text: str) -> bool:
    """Whether ``text`` reads as a ``--ray`` value: local, auto, HOST:PORT or ray://HOST:PORT."""
    return _ADDRESS.fullmatch(text) is not None


def transient_errors() -> tuple[type[BaseException], ...]:
    """Exceptions that mean the game instance crashed or lost its connection: worth a retry."""
    from sc2data import _pysc2  # noqa: F401 - fixes protobuf before pysc2.lib loads
    from pysc2.lib import protocol, remote_controller, sc_process  # isort: skip

    return (protocol.ConnectionError, remote_controller.ConnectError, sc_process.SC2LaunchError,
            ConnectionError, TimeoutError)


@dataclass(frozen=True)
class RayOptions:
    """Where and how tasks run; none of it changes the data."""

    address: str | None = None
    """None: start a local Ray instance; ``auto``, ``HOST:PORT`` or ``ray://HOST:PORT``: join
    that cluster. A process that has already called ``ray.init`` uses its own."""
    retries: int = DEFAULT_RETRIES
    """Extra attempts per task (worker died, instance crashed, hung)."""
    timeout_s: float = DEFAULT_TIMEOUT_S
    """Seconds without progress after which a task is cancelled and retried."""
    memory_mb: int | None = None
    """Memory to request per task (None: :data:`TASK_MEMORY_MB` or :data:`LABEL_MEMORY_MB`)."""
    workers: int | None = None
    """Tasks in flight at once (None: as many as Ray schedules); the CPUs of a local instance."""

    @classmethod
    def parse(cls, address: str, **kw: Any) -> RayOptions:
        """Options from the CLI's ``--ray ADDRESS`` (``local`` for a new local instance)."""
        if not is_address(address):
            raise Sc2DataError(f"--ray takes local, auto, HOST:PORT or ray://HOST:PORT, not "
                               f"{address!r}")
        return cls(address=None if address == "local" else address, **kw)

    def validate(self) -> None:
        if self.retries < 0:
            raise Sc2DataError(f"ray-retries must be 0 or more, not {self.retries}")
        if not self.timeout_s > 0:
            raise Sc2DataError(f"ray-timeout must be positive, not {self.timeout_s}")
        if self.memory_mb is not None and self.memory_mb < 1:
            raise Sc2DataError(f"ray-memory must be at least 1 MB, not {self.memory_mb}")
        if self.workers is not None and self.workers < 1:
            raise Sc2DataError(f"workers must be at least 1, not {self.workers}")


@contextlib.contextmanager
def connect(options: RayOptions) -> Iterator[Any]:
    """Ray, initialised as ``options`` say for the duration (and shut down after, if we did)."""
    ray = require_ray()
    if ray.is_initialized():
        yield ray
        return
    quiet = {"log_to_driver": False, "logging_level": "WARNING"}
    try:
        if options.address is None:
            # A worker killed mid-task (hang, OOM) would orphan its SC2 process: have the raylet
            # reap it (docs/ray.md says to set the same on every node of a cluster).
            os.environ.setdefault(SUBREAPER, "1")
            # "local": a new instance, even where `ray start` made one this machine's default.
            ray.init(address="local", num_cpus=options.workers or os.cpu_count(),
                     include_dashboard=False, object_store_memory=LOCAL_OBJECT_STORE, **quiet)
        else:
            ray.init(address=options.address, **quiet)
    except (ConnectionError, RuntimeError, ValueError) as e:
        where = "a local Ray instance" if options.address is None else \
            f"the Ray cluster at {options.address}"
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise Sc2DataError(f"cannot start or reach {where} ({first}); start one with "
                           f"`ray start --head`, or use --ray alone for a local one") from None
    try:
        yield ray
    finally:
        ray.shutdown()


_TRACKER: list[Any] = []
"""``[(node id, job id), handle]`` of this driver's tracker. Kept between runs, because starting
an actor's process takes seconds, and held here, because Ray ends an actor with its last handle."""

def _tracker(ray: Any) -> Any:
    """This driver's tracker, emptied."""
    ctx = ray.get_runtime_context()
    key = (ctx.get_node_id(), ctx.get_job_id())  # a new ray.init means a new node id
    if _TRACKER and _TRACKER[0] == key:
        with contextlib.suppress(ray.exceptions.RayActorError):
            ray.get(_TRACKER[1].reset.remote())
            return _TRACKER[1]
    _TRACKER[:] = [key, ray.remote(num_cpus=0)(Tracker).remote()]
    return _TRACKER[1]


# -- the parent -----------------------------------------------------------------------------------

@dataclass
class ScaleoutReport:
    """What a Ray run did beyond the plain case: retries and their reasons, and task memory."""

    results: dict[str, Any] = field(default_factory=dict, repr=False)
    """Task key -> what the task returned (a rollout task: its shard's index rows)."""
    retried: dict[str, list[str]] = field(default_factory=dict)
    """Task key (shard name) -> one line per attempt, in order, for tasks with more than one."""
    tasks: int = 0
    peak_rss_mb: float = 0.0
    """Largest peak RSS of a task's worker process."""
    peak_children_rss_mb: float = 0.0
    """Largest peak RSS of a process a task started and waited for (an SC2 instance)."""

    def lines(self) -> list[str]:
        mem = f"peak RSS per task {self.peak_rss_mb:.0f} MB"
        if self.peak_children_rss_mb:
            mem += f" (+ {self.peak_children_rss_mb:.0f} MB in its game process)"
        if not self.retried:
            return [f"ray: {self.tasks} tasks, none retried; {mem}"]
        out = [f"ray: {self.tasks} tasks, {len(self.retried)} retried; {mem}"]
        out += [f"  {key}: " + "; ".join(f"attempt {j + 1} {s}" for j, s in enumerate(lines))
                for key, lines in sorted(self.retried.items())]
        return out


@dataclass
class _Task:
    key: str
    args: tuple[Any, ...]
    seen: int = 0
    """Attempts of this key before the current submission."""
    max_retries: int = 0
    """Ray's retries for the current submission."""

def _outcomes(attempts: list[dict[str, Any]], cancelled: dict[str, str]) -> list[str]:
    """One line per attempt of a finished task: done (the last), or why it ended."""
    lines = []
    for j, a in enumerate(attempts):
        if a["token"] in cancelled:
            why = cancelled[a["token"]]
        elif a["error"] is not None:
            why = f"failed: {a['error']}"
        elif j == len(attempts) - 1:
            why = "done"
        else:
            why = "its worker process died (killed, out of memory, or its node was lost)"
        lines.append(f"({a['where']}): {why}")
    return lines


def _system_failure(ray: Any, e: BaseException) -> str:
    """Why Ray gave up on a task that raised no exception of its own."""
    if isinstance(e, ray.exceptions.OutOfMemoryError):
        return "killed by Ray for lack of memory (raise --ray-memory)"
    if isinstance(e, ray.exceptions.NodeDiedError):
        return "its node died"
    if isinstance(e, ray.exceptions.WorkerCrashedError):
        return "its worker process died (killed, out of memory, or crashed)"
    return f"{type(e).__name__}: {str(e).strip().splitlines()[0] if str(e).strip() else ''}"


class _Driver:
    """Runs tasks on Ray: at most ``options.workers`` in flight, each retried (by Ray for a dead
    worker, by us for a hang) up to ``options.retries`` times; progress comes from the tracker
    actor, which every attempt reports to."""

    def __init__(self, ray: Any, remote_fn: Any, tasks: list[_Task], options: RayOptions,
                 what: str) -> None:
        self.ray, self.remote_fn, self.tasks, self.options, self.what = \
            ray, remote_fn, tasks, options, what
        self.tracker = _tracker(ray)
        self.allowed = options.retries + 1
        self.waiting: deque[_Task] = deque(tasks)
        self.running: dict[Any, _Task] = {}
        self.cancelled: dict[str, str] = {}
        """Attempt token → why we cancelled it."""
        self.attempts: dict[str, list[dict[str, Any]]] = {}
        """Task key → its attempts, as the tracker last reported them."""
        self.report = ScaleoutReport(tasks=len(tasks))

    def submit(self, task: _Task) -> None:
        task.seen = len(self.attempts.get(task.key, ()))
        task.max_retries = self.allowed - 1 - task.seen
        ref = self.remote_fn.options(max_retries=task.max_retries).remote(*task.args,
                                                                          self.tracker)
        self.running[ref] = task

    def give_up(self, task: _Task, reason: str, n: int) -> Sc2DataError:
        return Sc2DataError(f"{self.what} of {task.key} failed after {n} attempt(s) (retries: "
                            f"{self.options.retries}): {reason}; rerun the same command to "
                            f"resume")

    def record(self, task: _Task) -> None:
        tries = self.attempts.get(task.key, [])
        if len(tries) > 1:
            self.report.retried[task.key] = _outcomes(tries, self.cancelled)

    def collect(self, ref: Any) -> None:
        """Take a finished task's result, or fail in one line."""
        ray, task = self.ray, self.running.pop(ref)
        try:
            result = ray.get(ref)
        except ray.exceptions.TaskCancelledError:
            return  # we cancelled it as hung; already resubmitted or failed
        except ray.exceptions.RayTaskError as e:
            cause = e.cause if e.cause is not None else e
            if not isinstance(cause, transient_errors()):
                raise Sc2DataError(f"{self.what} of {task.key} failed: "
                                   f"{one_line(cause)}") from None
            raise self.give_up(task, f"the instance crashed: {one_line(cause)}",
                               task.seen + task.max_retries + 1) from None
        except ray.exceptions.RayError as e:  # Ray retried it as often as allowed
            raise self.give_up(task, _system_failure(ray, e),
                               task.seen + task.max_retries + 1) from None
        r = self.report
        r.results[task.key] = result.get("rows")
        r.peak_rss_mb = max(r.peak_rss_mb, result["rss_mb"])
        r.peak_children_rss_mb = max(r.peak_children_rss_mb, result["children_rss_mb"])
        self.record(task)

    def cancel_hung(self) -> None:
        """Cancel and resubmit every task whose attempt made no progress for the timeout."""
        timeout = self.options.timeout_s
        for ref, task in list(self.running.items()):
            mine = self.attempts.get(task.key, [])[task.seen:]
            if not mine or mine[-1]["idle"] < timeout:
                continue
            self.cancelled[mine[-1]["token"]] = f"hung: no progress for {timeout:g} s, cancelled"
            self.ray.cancel(ref, force=True)
            del self.running[ref]
            if len(self.attempts[task.key]) >= self.allowed:
                raise self.give_up(task, f"no progress for {timeout:g} s (hung)",
                                   len(self.attempts[task.key]))
            self.submit(task)

    def run(self, bar: Bar) -> ScaleoutReport:
        ray, shown = self.ray, 0
        try:
            while self.waiting or self.running:
                while self.waiting and len(self.running) < (self.options.workers or
                                                            len(self.tasks)):
                    self.submit(self.waiting.popleft())
                ready, _ = ray.wait(list(self.running), num_returns=1, timeout=POLL_S)
                others = [r for r in self.running if r not in ready]
                if ready and others:  # and whatever else is finished by now
                    ready += ray.wait(others, num_returns=len(others), timeout=0)[0]
                self.attempts = ray.get(self.tracker.poll.remote())
                done = sum(v[-1]["done"] for v in self.attempts.values())
                bar.update(done - shown)
                shown = done
                for ref in ready:
                    self.collect(ref)
                self.cancel_hung()
            self.attempts = ray.get(self.tracker.poll.remote())
            for task in self.tasks:  # reasons that reached the tracker after the task's result
                if task.key in self.report.retried:
                    self.record(task)
            return self.report
        finally:
            for ref in self.running:  # failed or interrupted: stop the rest before cleaning up
                ray.cancel(ref, force=True)
            if self.running:
                ray.wait(list(self.running), num_returns=len(self.running), timeout=10)


def drive(ray: Any, remote_fn: Any, tasks: list[_Task], options: RayOptions, bar: Bar,
          what: str) -> ScaleoutReport:
    """Run ``tasks`` on Ray with retries and hang detection; feed ``bar``; fail in one line."""
    return _Driver(ray, remote_fn, tasks, options, what).run(bar)


# -- the two stages -------------------------------------------------------------------------------

def _memory(options: RayOptions, default_mb: int) -> int:
    return (options.memory_mb or default_mb) << 20


class RayShards:
    """A shard runner for :func:`sc2data.data.rollout.rollout`: shards as Ray tasks."""

    def __init__(self, options: RayOptions) -> None:
        self.options = options
        self.report = ScaleoutReport()

    def __call__(self, config: RolloutConfig, out: Path, todo: list[int],
                 env_factory: EnvFactory, agent_factory: AgentFactory, bar: Bar
                 ) -> dict[int, list[dict[str, Any]]]:
        from sc2data.data.dataset import shard_name

        if not todo:
            return {}
        ray = require_ray()
        fn = ray.remote(num_cpus=1, memory=_memory(self.options, TASK_MEMORY_MB[config.env]),
                        retry_exceptions=list(transient_errors()))(rollout_task)
        tasks = [_Task(shard_name(i), (config, str(out), i, env_factory, agent_factory,
                                       versions())) for i in todo]
        try:
            self.report = drive(ray, fn, tasks, self.options, bar, "rollout")
        finally:  # attempts of killed or cancelled tasks
            for stale in out.glob(f"shard-*{PARTIAL}"):
                shutil.rmtree(stale, ignore_errors=True)
        return {i: self.report.results[shard_name(i)] for i in todo}


def rollout_on_ray(config: RolloutConfig, out: str | os.PathLike[str], options: RayOptions,
                   progress: bool | None = None, env_factory: EnvFactory | None = None,
                   agent_factory: AgentFactory | None = None
                   ) -> tuple[RolloutSummary, ScaleoutReport]:
    """``sc2data rollout --ray``: :func:`sc2data.data.rollout.rollout` with shards as Ray tasks.

    Checks the settings and the folder before it starts or joins Ray; resumable as locally.
    Joining a cluster, the driver's machine needs no StarCraft II: each task checks its node.
    """
    from sc2data.data.rollout import check_folder, default_env_factory, rollout
    from sc2data.game import env as envs

    config.validate()
    options.validate()
    check_folder(config, Path(out))
    if env_factory is None and options.address is not None:
        env_factory = default_env_factory(config)  # skips rollout()'s check of this machine
    elif env_factory is None and config.env == "sc2" and not envs.sc2_available():
        envs.make_env("sc2")  # the install hint, before a local instance starts for nothing
    runner = RayShards(options)
    with connect(options):
        summary = rollout(config, out, progress=progress, env_factory=env_factory,
                          agent_factory=agent_factory, runner=runner)
    return summary, runner.report


class RayUnits:
    """A unit runner for :func:`sc2data.labels.label.label`: label units as Ray tasks."""

    def __init__(self, options: RayOptions, data: Path, selection: Selection) -> None:
        self.options, self.data, self.selection = options, data, selection
        self.report = ScaleoutReport()

    def __call__(self, todo: Sequence[tuple[WorkUnit, Path]], keys: Sequence[str], batch_size: int,
                 bar: Bar) -> None:
        if not todo:
            return
        ray = require_ray()
        fn = ray.remote(num_cpus=1, memory=_memory(self.options, LABEL_MEMORY_MB),
                        retry_exceptions=list(transient_errors()))(label_task)
        tasks = [_Task(unit.key.split(":")[0], (str(self.data), self.selection, unit.key,
                                                str(part), tuple(keys), batch_size))
                 for unit, part in todo]
        self.report = drive(ray, fn, tasks, self.options, bar, "label")


def label_on_ray(data: str | os.PathLike[str], options: RayOptions, *,
                 include: Sequence[str] | None = None, exclude: Sequence[str] = (),
                 rules_dir: Path | str | None = None, batch_size: int = 256,
                 progress: bool | None = None, overwrite: bool = False
                 ) -> tuple[LabelSummary, ScaleoutReport]:
    """``sc2data label --ray``: :func:`sc2data.labels.label.label_dataset` with units as Ray
    tasks."""
    from sc2data.labels.label import label_dataset

    options.validate()
    data = Path(data).resolve()
    rules = None if rules_dir is None else str(Path(rules_dir).resolve())
    runner = RayUnits(options, data, (include, tuple(exclude), rules))
    with connect(options):
        summary = label_dataset(data, include=include, exclude=exclude, rules_dir=rules_dir,
                                batch_size=batch_size, progress=progress, run_units=runner,
                                overwrite=overwrite)
    return summary, runner.report
