"""``sc2data build``: a recipe end to end — rollout → label → pair — resuming what is done.

The build folder holds the rolled-out dataset (with its labels) and the pair set::

    OUT/rollout/   shards, index.parquet, dataset.json, labels.parquet, stack_labels.parquet
    OUT/pairs/     pairs.parquet, pairset.json, packed/{train,val,test}.h5

Each stage resumes on its own terms (complete shards are kept, labelled shards are skipped, a
finished pair set from the same recipe and labels is kept), so rerunning after an interruption
only does what is left.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from sc2data.errors import Sc2DataError
from sc2data.files import LOCK, FolderLock, check_out
from sc2data.recipe import Recipe

if TYPE_CHECKING:
    from sc2data.data.rollout import RolloutConfig
    from sc2data.scaleout.driver import RayOptions

ROLLOUT_DIR = "rollout"
PAIRS_DIR = "pairs"


@dataclass
class BuildReport:
    """Seconds spent in each stage, and what each made."""

    out: Path
    seconds: dict[str, float] = field(default_factory=dict)
    lines: list[str] = field(default_factory=list)

    def table(self) -> str:
        rows = [f"{'stage':<8} {'seconds':>9}"] + [f"{k:<8} {v:>9.1f}" for k, v in
                                                   self.seconds.items()]
        rows.append(f"{'total':<8} {sum(self.seconds.values()):>9.1f}")
        return "\n".join(rows)


def build(recipe: Recipe, out: str | os.PathLike[str], *, workers: int = 1,
          progress: bool | None = None, ray: RayOptions | None = None,
          rules_dir: Path | str | None = None) -> BuildReport:
    """Run every stage of ``recipe`` into ``out``; stages already complete are kept.

    ``ray`` (:class:`sc2data.scaleout.driver.RayOptions`): roll out and label as Ray tasks, on one Ray
    instance or cluster for both stages; the data is the same either way.
    """
    from sc2data.data.rollout import RolloutConfig

    out = Path(out)
    report = BuildReport(out)
    data = out / ROLLOUT_DIR
    config = RolloutConfig.from_recipe(recipe)
    config.validate()
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
        raise Sc2DataError(f"cannot create {out}: {e.strerror or e}; choose another --out") \
            from None
    try:
        with FolderLock(out, "build"):
            return _stages(recipe, config, out, data, report, workers, progress, ray, rules_dir)
    finally:
        if made and [p.name for p in out.iterdir()] == [LOCK]:  # failed before writing anything
            shutil.rmtree(out, ignore_errors=True)


def _stages(recipe: Recipe, config: RolloutConfig, out: Path, data: Path, report: BuildReport,
            workers: int, progress: bool | None, ray: RayOptions | None,
            rules_dir: Path | str | None) -> BuildReport:
    """The three stages, under the build folder's lock."""
    from sc2data.data.rollout import check_folder, rollout
    from sc2data.labels.label import label_dataset
    from sc2data.pairs.pairset import make_pairset

    with contextlib.ExitStack() as stack:
        if ray is not None:
            from sc2data.scaleout.driver import connect, label_on_ray, rollout_on_ray

            config.validate()
            check_folder(config, data)  # before Ray starts for nothing
            stack.enter_context(connect(ray))

        t = time.perf_counter()
        if ray is None:
            r = rollout(config, data, workers=workers, progress=progress)
        else:
            r, retries = rollout_on_ray(config, data, ray, progress=progress)
            report.lines += retries.lines() if retries.tasks else []
        report.seconds["rollout"] = time.perf_counter() - t
        report.lines.append(f"rollout: {r.episodes} episodes, {r.steps:,} stacks "
                            f"({r.shards_written} shards written, {r.shards_kept} kept)")

        t = time.perf_counter()
        if ray is None:
            labels = label_dataset(data, include=list(recipe.rule_ids), progress=progress,
                                   workers=workers, rules_dir=rules_dir)
        else:
            labels, retries = label_on_ray(data, ray, include=list(recipe.rule_ids),
                                           progress=progress, rules_dir=rules_dir)
            report.lines += retries.lines() if retries.tasks else []
        report.seconds["label"] = time.perf_counter() - t
        report.lines.append(labels.table())

    t = time.perf_counter()
    pairs = make_pairset(recipe, data, out / PAIRS_DIR, progress=progress)
    report.seconds["pair"] = time.perf_counter() - t
    report.lines.append(pairs.table())
    return report
