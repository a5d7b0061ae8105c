"""Stored stacks drawn: one by (episode, step), or a sample of the stacks a rule fired on.

The dataset is read through :func:`sc2data.data.dataset.open_dataset`, the labels through
:func:`sc2data.labels.store.read_labels`, and each stack is drawn by
:func:`sc2data.game.render.render_stack` (every stored layer of both frames, with legends). It
lives in the labels room because a rule's stacks come from the label files.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from sc2data.data.dataset import Dataset, open_dataset
from sc2data.game.render import render_stack
from sc2data.ground.errors import Sc2DataError

DEFAULT_LIMIT = 8
"""Stacks drawn for ``--rule`` unless ``--limit`` says otherwise."""


def check_stack(ds: Dataset, episode: int, step: int) -> None:
    """A one-line error unless ``ds`` holds the stack (episode, step)."""
    ids = ds.episode_ids.tolist()
    if episode not in ids:
        span = f"episodes {ids[0]}..{ids[-1]}" if ids else "no episodes"
        raise Sc2DataError(f"episode {episode} is not in {ds.folder} ({span}); choose one of "
                           f"those with --episode")
    n = int(ds.n_steps[ids.index(episode)])
    if not 0 <= step < n:
        raise Sc2DataError(f"step {step} is outside episode {episode} of {ds.folder} (steps "
                           f"0..{n - 1}); choose one of those with --step")


def _draw(ds: Dataset, episode: int, step: int, title: str, out: Path) -> Path:
    try:
        batch = ds[episode, step]
    except OSError as e:
        raise Sc2DataError(f"{ds.folder} is unreadable ({e}); run sc2data verify "
                           f"{ds.folder}") from None
    return render_stack(batch, f"{title}   episode {episode}   step {step}", out)


def render_stored(data: str | os.PathLike[str], episode: int, step: int, out: str | Path
                  ) -> Path:
    """Write a PNG of the stored stack (episode, step) of the dataset folder ``data``."""
    with open_dataset(data) as ds:
        check_stack(ds, episode, step)
        return _draw(ds, episode, step, str(data), Path(out))


def fired_on(data: str | os.PathLike[str], rule_id: str) -> list[tuple[int, int]]:
    """Every (episode, step) the rule fired on in ``data``'s labels, in that order; a one-line
    error saying what to run where the folder is not a labelled dataset, its labels come from
    other data, the rule is not among them or fired nowhere."""
    from sc2data.labels.source import dataset_source
    from sc2data.labels.store import read_labels

    source = dataset_source(data)  # first, so that a folder that is no dataset says so
    labels = read_labels(data)
    if labels.meta.get("dataset", {}).get("fingerprint") != source.info["fingerprint"]:
        raise Sc2DataError(f"the labels of {data} were made from other data (its shards changed "
                           f"since); rerun sc2data label {data}")
    ids = [r["id"] for r in labels.meta["rules"]]
    if rule_id not in ids:
        raise Sc2DataError(f"rule {rule_id!r} is not among the labels of {data} (labelled with: "
                           f"{', '.join(ids)}); label with it: sc2data label {data} --rules "
                           f"{','.join([*ids, rule_id])} --overwrite (with --rules-dir for a "
                           f"rule of yours)")
    t = labels.fired
    mask = np.asarray(t.column("rule_id").to_pylist(), dtype=object) == rule_id
    episodes = t.column("episode").to_numpy()[mask]
    steps = t.column("step").to_numpy()[mask]
    if not len(episodes):
        raise Sc2DataError(f"rule {rule_id!r} fired on none of the {labels.meta['stacks']:,} "
                           f"stacks of {data}; nothing to draw (roll out more episodes?)")
    order = np.lexsort((steps, episodes))
    return [(int(episodes[i]), int(steps[i])) for i in order]


def spread(n: int, limit: int) -> list[int]:
    """``min(limit, n)`` positions spread evenly over ``range(n)``, first and last included."""
    if limit == 1:
        return [0]
    return sorted(set(np.linspace(0, n - 1, min(limit, n)).round().astype(int).tolist()))


def render_rule(data: str | os.PathLike[str], rule_id: str, out_dir: str | Path,
                limit: int = DEFAULT_LIMIT) -> list[Path]:
    """Write one PNG per stack for up to ``limit`` stacks the rule fired on, spread evenly over
    all of them in (episode, step) order, as ``out_dir/e<episode>-s<step>.png``."""
    if limit < 1:
        raise Sc2DataError(f"--limit must be at least 1, not {limit}")
    picks = fired_on(data, rule_id)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise Sc2DataError(f"{out} is a file; with --rule, --out names a folder for the PNGs")
    chosen = spread(len(picks), limit)
    paths = []
    with open_dataset(data) as ds:
        for i in chosen:
            episode, step = picks[i]
            check_stack(ds, episode, step)
            title = f"{data}   rule {rule_id}: fired on {len(picks):,} stacks, this is #{i + 1}"
            paths.append(_draw(ds, episode, step, title, out / f"e{episode}-s{step}.png"))
    return paths
