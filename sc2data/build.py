"""``sc2data build``: a recipe end to end — rollout → label → pair — resuming what is done.

The build folder holds the rolled-out dataset (with its labels) and the pair set::

    OUT/rollout/   shards, index.parquet, dataset.json, labels.parquet, stack_labels.parquet
    OUT/pairs/     pairs.parquet, pairset.json, packed/{train,val,test}.h5

Each stage resumes on its own terms (complete shards are kept, labelled shards are skipped, a
finished pair set from the same recipe and labels is kept), so rerunning after an interruption
only does what is left.

When the pair stage finds too few states, the build grows the data to the episodes it asks for
(rollout adds them, label relabels) and pairs again: at most :data:`GROW_ROUNDS` times, never
past :data:`GROW_LIMIT` times the recipe's episodes; past that, or when a command never fires,
it ends with one line saying what the recipe needs. The data never shrinks: a rerun keeps the
episodes an earlier build grew it to.
"""

from __future__ import annotations

import os
import shutil
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from sc2data.cli.cliopts import plural
from sc2data.ground.errors import Sc2DataError, reason
from sc2data.ground.files import LOCK, FolderLock, check_out
from sc2data.ground.recipe import MAX_EPISODES, Recipe

if TYPE_CHECKING:
    from sc2data.data.rollout import RolloutConfig
    from sc2data.pairs.draw import NotEnoughStates
    from sc2data.scaleout.driver import RayOptions

ROLLOUT_DIR = "rollout"
PAIRS_DIR = "pairs"
GROW_ROUNDS = 3
"""Times a build grows its data on its own when the pair stage finds too few states."""
GROW_LIMIT = 10
"""A build grows its data to at most this many times the recipe's episodes."""


@dataclass
class BuildReport:
    """Seconds spent in each stage, and what each made."""

    out: Path
    seconds: dict[str, float] = field(default_factory=dict)
    lines: list[str] = field(default_factory=list)

    def add(self, stage: str, started: float) -> None:
        """Count the seconds since ``started`` (``time.perf_counter()``) to ``stage``."""
        self.seconds[stage] = self.seconds.get(stage, 0.0) + time.perf_counter() - started

    def table(self) -> str:
        rows = [f"{'stage':<8} {'seconds':>9}"] + [f"{k:<8} {v:>9.1f}" for k, v in
                                                   self.seconds.items()]
        rows.append(f"{'total':<8} {sum(self.seconds.values()):>9.1f}")
        return "\n".join(rows)


def build(recipe: Recipe, out: str | os.PathLike[str], *, workers: int = 1,
          progress: bool | None = None, ray: RayOptions | None = None,
          rules_dir: Path | str | None = None) -> BuildReport:
    """Run every stage of ``recipe`` into ``out``; stages already complete are kept.

    ``ray`` (:class:`sc2data.scaleout.driver.RayOptions`): roll out and label as Ray tasks, on
    one Ray
    instance or cluster for both stages; the data is the same either way. Grows the data when
    the pair stage finds too few states (see the module's docstring).
    """
    from sc2data.data.rollout import RolloutConfig, folder_config

    out = Path(out)
    report = BuildReport(out)
    data = out / ROLLOUT_DIR
    config = RolloutConfig.from_recipe(recipe)
    config.validate()
    grown = folder_config(data)  # the data an earlier build grew is kept, never shrunk
    if grown is not None and grown.episodes > config.episodes:
        report.lines.append(f"rollout: keeping the {grown.episodes} episodes an earlier build "
                            f"grew the data to (the recipe asks for {config.episodes})")
        config = replace(config, episodes=grown.episodes)
    # Every rule the recipe names exists and can read the layers it rolls out, before any work.
    from sc2data.labels.apply import check_requirements
    from sc2data.labels.registry import load_registry

    rules = load_registry(rules_dir).select(list(recipe.rule_ids))
    check_requirements(rules, config.schema, f"recipe {recipe.name!r} ({config.layers} layers)")
    if out.exists() and not out.is_dir():
        raise Sc2DataError(f"output {out} exists and is not a folder; choose another --out")
    check_out(out)
    made = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise Sc2DataError(f"cannot create {out}: {reason(e)}; choose another --out") \
            from None
    try:
        with FolderLock(out, "build", remove=True):
            return _stages(recipe, config, out=out, data=data, report=report, workers=workers,
                           progress=progress, ray=ray, rules_dir=rules_dir)
    finally:
        if made and [p.name for p in out.iterdir()] in ([LOCK], []):  # failed before any write
            shutil.rmtree(out, ignore_errors=True)


def grow_to(shortage: NotEnoughStates, have: int, asked: int, rounds: int) -> int:
    """The episodes to grow the data to after ``shortage`` (the data has ``have``, the recipe
    asks for ``asked``, the build has grown it ``rounds`` times), or the error that ends it."""
    from sc2data.pairs.draw import NotEnoughStates

    if shortage.episodes is None:
        raise shortage  # more data cannot help: it says why
    want = max(shortage.episodes, have + 1)
    limit = min(MAX_EPISODES, GROW_LIMIT * asked)
    if rounds < GROW_ROUNDS and want <= limit:
        return want
    raise NotEnoughStates(shortage.shortfall, f"it needs about {want} episodes, and sc2data build "
                          f"grows the data at most {GROW_ROUNDS} times, to at most {GROW_LIMIT}× "
                          f"the recipe's {asked} episodes (grown {rounds} times so far); set "
                          f"[rollout] episodes = {want} in the recipe and rerun", None)


def _stages(recipe: Recipe, config: RolloutConfig, *, out: Path, data: Path, report: BuildReport,
            workers: int, progress: bool | None, ray: RayOptions | None,
            rules_dir: Path | str | None) -> BuildReport:
    """The three stages, under the build folder's lock; the first two again for each grow."""
    from sc2data.pairs.draw import NotEnoughStates
    from sc2data.pairs.pairset import make_pairset

    for rounds in range(GROW_ROUNDS + 1):
        _data(recipe, config, data=data, report=report, workers=workers, progress=progress,
              ray=ray, rules_dir=rules_dir)
        t = time.perf_counter()
        try:
            pairs = make_pairset(recipe, data, out / PAIRS_DIR, progress=progress)
        except NotEnoughStates as e:
            report.add("pair", t)
            episodes = grow_to(e, config.episodes, recipe.rollout.episodes, rounds)
            report.lines.append(f"pair: {e.shortfall}; growing the data to {episodes} episodes")
            config = replace(config, episodes=episodes)
            continue
        report.add("pair", t)
        report.lines.append(pairs.table())
        return report
    raise AssertionError("grow_to ends the build after GROW_ROUNDS rounds")


def _data(recipe: Recipe, config: RolloutConfig, *, data: Path, report: BuildReport, workers: int,
          progress: bool | None, ray: RayOptions | None, rules_dir: Path | str | None) -> None:
    """Roll out and label ``config``'s data (on one Ray instance or cluster with ``ray``)."""
    from sc2data.scaleout.where import run_label, run_rollout, session

    with session(ray, config, data):  # one Ray instance for both stages, with --ray
        t = time.perf_counter()
        r, retries = run_rollout(config, data, workers=workers, progress=progress, ray=ray)
        report.lines += retries
        report.add("rollout", t)
        grew = f", grown from {r.grew_from}" if r.grew_from is not None else ""
        report.lines.append(f"rollout: {plural(r.episodes, 'episode')}{grew}, "
                            f"{plural(r.steps, 'stack')} ({plural(r.shards_written, 'shard')} "
                            f"written, {r.shards_kept} kept)")

        t = time.perf_counter()
        labels, retries = run_label(data, workers=workers, ray=ray, include=list(recipe.rule_ids),
                                    progress=progress, rules_dir=rules_dir)
        report.lines += retries
        report.add("label", t)
        report.lines.append(labels.table())
