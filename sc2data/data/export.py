"""``sc2data export``: a rolled-out dataset in the formats other tools read — plain numpy
(``npz``), a Minari dataset (``minari``) or a Hugging Face ``datasets`` dataset (``hf``).

Every format holds the same episodes, in the RL convention: an episode of ``T`` steps has
``T + 1`` observations (frame 0 before the first action … frame ``T`` after the last), ``T``
actions, ``T`` rewards and ``T`` terminations and truncations. An observation is one frame of
the dataset's schema, nested as ``{"screen": {layer: (64, 64)}, "minimap": {layer: (64, 64)},
vector: (n,)}`` in the stored (lossless) dtypes; an action is the pysc2 call the agent made,
``{"function": id, "args": (ARG_WIDTH,) int16}`` (its arguments flattened, ``-1`` padded;
:func:`sc2data.data.shards.function_call` rebuilds the ``FunctionCall``); a reward is what the
game returned for it (+1 per marine on BuildMarines). ``terminations[T-1]`` is True where the game
ended the episode (pysc2's last step, discount 0), ``truncations[T-1]`` where the rollout's
``--max-steps`` cut it. Where the dataset keeps action masks (format 4 on), each observation
also has its ``available_actions``: a boolean mask over pysc2's ``actions.FUNCTIONS``, ``(T + 1,
573)`` per episode (row ``t`` masks the choice of action ``t``).

* ``npz``: a folder of ``episode-<E>.npz`` files (``np.load``; keys ``observations/screen/…``,
  ``actions/function``, ``actions/args``, ``rewards``, ``terminations``, ``truncations``,
  ``available_actions``) and ``metadata.json``;
* ``minari``: a Minari datasets root holding ``sc2data/<name>-v0`` (``minari.load_dataset`` with
  ``MINARI_DATASETS_PATH`` set to it), made with ``minari.create_dataset_from_buffers``, its
  spaces gymnasium ``Dict``\\ s of ``Box``\\ es and a ``Discrete`` function id, the masks in
  ``infos["available_actions"]``;
* ``hf``: a ``datasets.Dataset`` saved with ``save_to_disk`` (Arrow; ``datasets.load_from_disk``),
  one row per step — the stack's two frames as ``observation.<key>`` and
  ``next_observation.<key>`` columns (``observation.screen.unit_type``), the action (``function``,
  ``args``), ``reward``, ``terminated`` and ``truncated``, and the masks of both frames,
  ``available_actions`` and ``next_available_actions`` — so that ``shuffle`` and batching work
  on transitions.

The export is written under a temporary ``….partial`` name beside ``--out`` and renamed into
place when complete, so an interrupted export leaves nothing that looks finished; the next
export into that ``--out`` removes what a killed one left (``OUT.PID.partial``), and a rerun of
an export stopped after its rename (``OUT`` already this export, by its ``metadata.json``)
exports it again rather than refusing the existing ``OUT``.
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import re
import shutil
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.data.dataset import Dataset
from sc2data.data.shards import ARG_WIDTH
from sc2data.ground.errors import MissingDependencyError, Sc2DataError, reason
from sc2data.ground.files import PARTIAL, check_out, fsync_path, publish, writing
from sc2data.ground.formats import loads
from sc2data.ground.progress import bar
from sc2data.ground.provenance import versions
from sc2data.ground.vocab import EPISODE_STEPS
from sc2data.schema import Schema

FORMATS = ("npz", "minari", "hf")
"""What ``--to`` takes."""
_READ_STEPS = 256
"""Stacks read at a time while an episode's frames are gathered."""

@dataclass(frozen=True)
class Episode:
    """One episode in the RL convention (see the module docstring)."""

    id: int
    observations: dict[str, np.ndarray]
    """Schema key → ``(T + 1, …)``: frames 0 … T."""
    function: np.ndarray
    """``(T,)`` int64 pysc2 function ids."""
    args: np.ndarray
    """``(T, ARG_WIDTH)`` int16 flattened arguments, ``-1`` padded."""
    rewards: np.ndarray
    """``(T,)`` float64."""
    terminations: np.ndarray
    truncations: np.ndarray
    available: np.ndarray | None = None
    """``(T + 1, len(actions.FUNCTIONS))`` bool: each frame's ``available_actions`` (None for a
    dataset written before masks were kept)."""

    def __repr__(self) -> str:
        return f"Episode(id={self.id}, steps={len(self.function)}, keys={len(self.observations)})"


@dataclass(frozen=True)
class ExportSummary:
    out: Path
    to: str
    episodes: int
    steps: int
    bytes: int
    seconds: float
    read_with: str
    """One line of Python that reads the export back."""

def episode(ds: Dataset, episode_id: int, settings: dict[str, Any]) -> Episode:
    """Episode ``episode_id`` of ``ds``, its frames gathered from its stacks."""
    row = int(np.searchsorted(ds.episode_ids, episode_id))
    n = int(ds.n_steps[row])
    frames: dict[str, list[np.ndarray]] = {k: [] for k in ds.schema.keys()}
    for start in range(0, n, _READ_STEPS):
        steps = np.arange(start, min(start + _READ_STEPS, n))
        arrays = ds.read(np.full(len(steps), episode_id), steps).arrays
        last = start + _READ_STEPS >= n
        for k, a in arrays.items():
            frames[k].append(a[:, 0])
            if last:
                frames[k].append(a[-1:, 1])
    acts = ds.actions(np.full(n, episode_id), np.arange(n))
    max_steps = settings.get("max_steps")
    ended = max_steps is None or n < int(max_steps) or n == EPISODE_STEPS
    end = np.zeros(n, bool)
    if n:
        end[-1] = True
    available = None
    if "available" in acts:
        available = np.concatenate([acts["available"], acts["next_available"][-1:]])
    return Episode(id=int(episode_id),
                   observations={k: np.concatenate(v) for k, v in frames.items()},
                   function=acts["function"].astype(np.int64), args=acts["args"],
                   rewards=acts["reward"].astype(np.float64),
                   terminations=end & ended, truncations=end & (not ended), available=available)


def nested(flat: dict[str, Any]) -> dict[str, Any]:
    """``{"screen/unit_type": a, "player": b}`` → ``{"player": b, "screen": {"unit_type": a}}``,
    keys sorted at every level as gymnasium's ``Dict`` space sorts them (Minari's storage pairs
    a dict's values with its space's keys in order)."""
    out: dict[str, Any] = {}
    for key, value in flat.items():
        group, _, name = key.rpartition("/")
        (out.setdefault(group, {}) if group else out)[name] = value
    return {k: dict(sorted(v.items())) if isinstance(v, dict) else v
            for k, v in sorted(out.items())}


def metadata(ds: Dataset, to: str, name: str, episodes: int, steps: int) -> dict[str, Any]:
    """What every export records of its source (``metadata.json``, Minari's description, the
    Hugging Face dataset's ``info.description``)."""

    return {"format": f"sc2data-export-{to}", "name": name, "source": str(ds.folder.resolve()),
            "episodes": episodes, "steps": steps, "settings": ds.settings,
            "schema": ds.schema.to_dict(), "arg_width": ARG_WIDTH, "versions": versions(),
            "actions": "function: pysc2 function id; args: its arguments flattened, -1 padded "
                       "(sc2data.data.shards.function_call rebuilds the FunctionCall)",
            "rewards": "the game's reward for the step (+1 per marine on BuildMarines)",
            "available_actions": ("each frame's pysc2 available_actions as a boolean mask over "
                                  "pysc2's actions.FUNCTIONS; row t masks the choice of action t")
            if ds.has_masks else "not kept (a dataset written before format 4)"}


def export(data: str | os.PathLike[str], to: str, out: str | os.PathLike[str], *,
           name: str | None = None, episodes: int | None = None, overwrite: bool = False,
           progress: bool | None = None) -> ExportSummary:
    """Write the episodes of the dataset folder ``data`` (all, or the first ``episodes``) to
    ``out`` in format ``to``."""
    if to not in FORMATS:
        raise Sc2DataError(f"unknown export format {to!r}; choose one of: {', '.join(FORMATS)}")
    if episodes is not None and episodes < 1:
        raise Sc2DataError(f"--episodes must be at least 1, not {episodes}")
    writer = {"npz": _write_npz, "minari": _write_minari, "hf": _write_hf}[to]
    _require(to)
    src, out = Path(data), Path(out)
    name = _name(name if name is not None else src.resolve().name)
    t0 = time.perf_counter()
    with Dataset(src) as ds:
        ids = ds.episode_ids[:episodes].tolist()
        stacks = int(ds.n_steps[:len(ids)].sum())
        if out.exists() and not overwrite and not _this_export(
                out, metadata(ds, to, name, len(ids), stacks)):
            raise Sc2DataError(f"{out} exists; choose another --out, or pass --overwrite to "
                               f"replace it")
        if out.exists() and not out.is_dir():
            raise Sc2DataError(f"{out} is a file; choose another --out")
        check_out(out)
        _sweep(out)
        tmp = out.with_name(f"{out.name}.{os.getpid()}{PARTIAL}")
        shutil.rmtree(tmp, ignore_errors=True)

        try:
            with writing(str(out), "free some space, then export again"):
                tmp.mkdir(parents=True)
                with bar(stacks, desc=f"export {to}", unit="stack", show=progress) as b:
                    def each() -> Iterator[Episode]:
                        for e in ids:
                            ep = episode(ds, int(e), ds.settings)
                            b.update(len(ep.function))
                            yield ep

                    read_with = writer(ds, each(), tmp, name, len(ids), stacks)
                for path in sorted(tmp.rglob("*")):
                    if path.is_file():
                        fsync_path(path)
                _replace(tmp, out)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
        return ExportSummary(out, to, len(ids), stacks, size,
                             time.perf_counter() - t0, read_with.format(out=out))


def _this_export(out: Path, meta: dict[str, Any]) -> bool:
    """``out`` is this very export, finished by an earlier run of the command (one stopped as it
    exited, after the rename): its ``metadata.json`` records the same format, name, source,
    episodes, settings and versions. A rerun then exports it again, as the line of a stopped
    run says to (a Minari export keeps no ``metadata.json``: ``--overwrite`` replaces it)."""
    try:
        old = loads((out / "metadata.json").read_bytes())
    except (OSError, ValueError):
        return False
    meta = json.loads(json.dumps(meta))  # as written: tuples are lists
    return isinstance(old, dict) and all(old.get(k) == v for k, v in meta.items())


def _sweep(out: Path) -> None:
    """Remove what a killed export into ``out`` left beside it: ``OUT.PID.partial`` and
    ``OUT.old.PID.partial`` of a process that no longer runs (those of a running export are
    its own)."""
    for path in out.parent.glob(f"{glob.escape(out.name)}.*{PARTIAL}"):
        pid = path.name[len(out.name) + 1:-len(PARTIAL)].removeprefix("old.")
        if pid.isdigit() and int(pid) != os.getpid() and not _running(int(pid)):
            shutil.rmtree(path, ignore_errors=True)


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def _replace(tmp: Path, out: Path) -> None:
    """Give the finished ``tmp`` the name ``out`` (an old ``out`` is removed once it has)."""
    old = None
    if out.exists():
        old = out.with_name(f"{out.name}.old.{os.getpid()}{PARTIAL}")
        os.replace(out, old)
    try:
        publish(tmp, out)
    except OSError as e:
        if old is not None:
            os.replace(old, out)
        raise Sc2DataError(f"cannot write {out}: {reason(e)}; choose another --out") from None
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _name(name: str) -> str:
    """A dataset name as Minari ids allow it: lowercase letters, digits, ``_`` and ``-``."""
    slug = re.sub(r"[^a-z0-9_]+", "-", name.lower()).strip("-")
    if not slug:
        raise Sc2DataError(f"--name {name!r} has no letter or digit; give a name like "
                           f"buildmarines-random")
    return slug


_EXTRA = {"npz": (), "minari": ("minari", "gymnasium"), "hf": ("datasets",)}


def _require(to: str) -> None:
    """A one-line error naming the ``export`` extra unless ``to``'s packages import."""
    for module in _EXTRA[to]:
        try:
            __import__(module)
        except ImportError:
            raise MissingDependencyError(module, "export", f"sc2data export --to {to}") from None


# -- npz -------------------------------------------------------------------------------------------
def _write_npz(ds: Dataset, episodes: Iterator[Episode], tmp: Path, name: str, n: int,
               steps: int) -> str:
    meta = metadata(ds, "npz", name, n, steps)
    meta["files"] = "episode-<E>.npz, E the episode id (6 digits)"
    for ep in episodes:
        arrays = {f"observations/{k}": v for k, v in ep.observations.items()}
        arrays.update({"actions/function": ep.function, "actions/args": ep.args,
                       "rewards": ep.rewards, "terminations": ep.terminations,
                       "truncations": ep.truncations})
        if ep.available is not None:
            arrays["available_actions"] = ep.available
        np.savez_compressed(tmp / f"episode-{ep.id:06d}.npz", **arrays)  # type: ignore[arg-type]
    (tmp / "metadata.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return "np.load('{out}/episode-000000.npz')['observations/screen/unit_type']"


# -- Minari ----------------------------------------------------------------------------------------
def spaces(schema: Schema) -> tuple[Any, Any]:
    """(observation space, action space) as gymnasium spaces: a nested ``Dict`` of ``Box``\\ es in
    the stored dtypes, and ``Dict(function=Discrete, args=Box)``."""
    from gymnasium import spaces as gs

    from sc2data._pysc2 import actions

    flat: dict[str, Any] = {}
    for l in schema.layers:
        side = schema.size(l.group)
        top = (l.scale if l.categorical else l.limit) - 1
        flat[l.key] = gs.Box(0, top, (side, side), l.dtype)
    for v in schema.vectors:
        info = np.iinfo(v.dtype) if v.dtype.kind in "iu" else np.finfo(v.dtype)
        flat[v.name] = gs.Box(info.min, info.max, (v.size,), v.dtype)
    obs = gs.Dict({k: gs.Dict(v) if isinstance(v, dict) else v
                   for k, v in nested(flat).items()})
    act = gs.Dict({"function": gs.Discrete(len(actions.FUNCTIONS)),
                   "args": gs.Box(-1, np.iinfo(np.int16).max, (ARG_WIDTH,), np.int16)})
    return obs, act


@contextlib.contextmanager
def _lossless_minari() -> Iterator[None]:
    """Minari stores a ``uint8`` ``Box`` of 32×32 or more with values 0…255 as JPEG unless told
    not to (``MinariStorage.new(jpeg_encoding=False)``), which ``create_dataset_from_buffers``
    cannot be; for the time of the block, every storage it makes is made lossless."""
    import inspect

    from minari.dataset.minari_storage import MinariStorage

    new = MinariStorage.__dict__["new"]
    if "jpeg_encoding" not in inspect.signature(MinariStorage.new).parameters:
        yield  # a Minari that never encodes
        return

    def lossless(cls: type, *args: Any, **kwargs: Any) -> Any:
        kwargs["jpeg_encoding"] = False
        return new.__func__(cls, *args, **kwargs)

    MinariStorage.new = classmethod(lossless)  # type: ignore[method-assign, assignment]
    try:
        yield
    finally:
        MinariStorage.new = new  # type: ignore[method-assign]


def _write_minari(ds: Dataset, episodes: Iterator[Episode], tmp: Path, name: str, n: int,
                  steps: int) -> str:
    import minari
    from minari.data_collector import EpisodeBuffer

    obs_space, act_space = spaces(ds.schema)
    dataset_id = f"sc2data/{name}-v0"
    meta = metadata(ds, "minari", name, n, steps)
    description = (f"sc2data rollout of StarCraft II BuildMarines ({meta['settings'].get('env')}"
                   f" env, {meta['settings'].get('agent')} agent, {meta['episodes']} episodes): "
                   f"{meta['actions']}; rewards: {meta['rewards']}. Source: {meta['source']}.")

    def buffers() -> Iterator[Any]:
        for ep in episodes:
            yield EpisodeBuffer(
                observations=nested(ep.observations),
                actions={"function": ep.function, "args": ep.args}, rewards=ep.rewards,
                terminations=ep.terminations, truncations=ep.truncations,
                infos={} if ep.available is None else {"available_actions": ep.available})

    previous = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(tmp.resolve())  # Minari joins a relative one twice
    try:
        with warnings.catch_warnings(), _lossless_minari():
            warnings.simplefilter("ignore", UserWarning)  # no author, e-mail or code link to give
            minari.create_dataset_from_buffers(
                dataset_id, buffers(), observation_space=obs_space, action_space=act_space,
                algorithm_name=f"sc2data rollout --agent {meta['settings'].get('agent')}",
                description=description, data_format="hdf5")
    finally:
        if previous is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = previous
    return (f"MINARI_DATASETS_PATH={{out}} python -c \"import minari; "
            f"minari.load_dataset('{dataset_id}')\"")


# -- Hugging Face datasets -------------------------------------------------------------------------
def hf_column(prefix: str, key: str) -> str:
    """A frame key's column: ``observation.screen.unit_type``, ``next_observation.player``."""
    return f"{prefix}.{key.replace('/', '.')}"


def hf_features(schema: Schema, masks: bool = False) -> Any:
    """The ``datasets.Features`` of one row (one step): flat columns, so that a numpy-formatted
    batch gives one ``(B, …)`` array per layer; ``masks``: with both frames' action masks."""
    import datasets
    import datasets.utils.tqdm

    from sc2data._pysc2 import actions

    frame: dict[str, Any] = {}
    for l in schema.layers:
        side = schema.size(l.group)
        frame[l.key] = datasets.Array2D((side, side), l.dtype.name)
    for v in schema.vectors:
        frame[v.name] = datasets.Sequence(datasets.Value(v.dtype.name), length=v.size)
    columns: dict[str, Any] = {"episode": datasets.Value("int64"), "step": datasets.Value("int64")}
    for prefix in ("observation", "next_observation"):
        columns.update({hf_column(prefix, k): f for k, f in frame.items()})
    columns.update({"function": datasets.Value("int64"),
                    "args": datasets.Sequence(datasets.Value("int16"), length=ARG_WIDTH),
                    "reward": datasets.Value("float64"), "terminated": datasets.Value("bool"),
                    "truncated": datasets.Value("bool")})
    if masks:
        mask = datasets.Sequence(datasets.Value("bool"), length=len(actions.FUNCTIONS))
        columns.update({"available_actions": mask, "next_available_actions": mask})
    return datasets.Features(columns)


def _rows(episodes: Iterator[Episode]) -> Iterator[dict[str, Any]]:
    for ep in episodes:
        for t in range(len(ep.function)):
            row: dict[str, Any] = {"episode": ep.id, "step": t}
            for prefix, at in (("observation", t), ("next_observation", t + 1)):
                row.update({hf_column(prefix, k): v[at] for k, v in ep.observations.items()})
            row.update({"function": int(ep.function[t]), "args": ep.args[t],
                        "reward": float(ep.rewards[t]), "terminated": bool(ep.terminations[t]),
                        "truncated": bool(ep.truncations[t])})
            if ep.available is not None:
                row.update({"available_actions": ep.available[t],
                            "next_available_actions": ep.available[t + 1]})
            yield row


def _write_hf(ds: Dataset, episodes: Iterator[Episode], tmp: Path, name: str, n: int,
              steps: int) -> str:
    import datasets
    from datasets.arrow_writer import ArrowWriter

    meta = metadata(ds, "hf", name, n, steps)
    features = hf_features(ds.schema, ds.has_masks)
    arrow = tmp / "rows.arrow"  # written once, then saved as the dataset's own shards
    with ArrowWriter(features=features, path=str(arrow), writer_batch_size=64) as w:
        for row in _rows(episodes):
            w.write(row)
        w.finalize()
    info = datasets.DatasetInfo(description=json.dumps(meta, sort_keys=True), features=features)
    built = datasets.Dataset.from_file(str(arrow), info=info)
    shown = datasets.is_progress_bar_enabled()
    datasets.disable_progress_bars()  # our own bar has shown the work
    try:
        built.save_to_disk(str(tmp / "dataset"))
    finally:
        if shown:
            datasets.enable_progress_bars()
    del built
    arrow.unlink()
    (tmp / "metadata.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return "datasets.load_from_disk('{out}/dataset').with_format('numpy')"


__all__ = ["FORMATS", "Episode", "ExportSummary", "episode", "export", "hf_column", "hf_features",
           "nested", "spaces"]
