"""``sc2data export``: each format read back by its own library equals the dataset it came from;
bad input is one line; an interrupted export leaves nothing that looks finished."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from sc2data.data.dataset import open_dataset
from sc2data.data.export import hf_column
from tests.cli import assert_one_line_error, run_cli
from tests.synthetic_data import STEPS, make_dataset

EPISODES = 3


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("export") / "data"
    make_dataset(out, episodes=EPISODES)
    return out


@pytest.fixture(scope="module")
def cut(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Episodes cut by --max-steps: truncated, not terminated."""
    out = tmp_path_factory.mktemp("export-cut") / "cut"
    make_dataset(out, episodes=1, max_steps=STEPS - 5)
    return out


def expected(folder: Path) -> list[dict[str, object]]:
    """Each episode straight from the dataset reader: frames 0…T and the T actions."""
    ds = open_dataset(folder)
    out = []
    for e, n in zip(ds.episode_ids.tolist(), ds.n_steps.tolist()):
        stacks = ds[e, 0:n].arrays
        frames = {k: np.concatenate([v[:, 0], v[-1:, 1]]) for k, v in stacks.items()}
        acts = ds.actions([e] * n, range(n))
        masks = np.concatenate([acts["available"], acts["next_available"][-1:]])
        assert masks.shape == (n + 1, 573) and masks.any(axis=1).all()
        out.append({"id": e, "frames": frames, "masks": masks, **acts})
    return out


def nested_get(tree: dict[str, object], key: str) -> np.ndarray:
    for part in key.split("/"):
        tree = tree[part]  # type: ignore[assignment]
    return np.asarray(tree)


def test_npz_reads_back_with_numpy(data: Path, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "npz"
    code, stdout, err = run_cli(["export", data, "--to", "npz", "--out", out, "--no-progress"],
                                capsys)
    assert code == 0, err
    assert f"{EPISODES} episodes" in stdout and "read it with: np.load(" in stdout
    files = sorted(p.name for p in out.iterdir())
    assert files == ["episode-000000.npz", "episode-000001.npz", "episode-000002.npz",
                     "metadata.json"]
    meta = json.loads((out / "metadata.json").read_text())
    assert meta["episodes"] == EPISODES and meta["schema"]["screen"]
    for ep in expected(data):
        with np.load(out / f"episode-{ep['id']:06d}.npz") as z:
            for k, v in ep["frames"].items():  # type: ignore[attr-defined]
                got = z[f"observations/{k}"]
                assert got.dtype == v.dtype and np.array_equal(got, v), k
                assert len(got) == STEPS + 1
            assert np.array_equal(z["actions/function"], ep["function"])
            assert np.array_equal(z["actions/args"], ep["args"])
            assert np.array_equal(z["rewards"], ep["reward"])
            assert z["terminations"].tolist() == [False] * (STEPS - 1) + [True]
            assert not z["truncations"].any()
            assert z["available_actions"].dtype == bool
            assert np.array_equal(z["available_actions"], ep["masks"])


def test_minari_reads_back_with_minari(data: Path, tmp_path: Path,
                                       monkeypatch: pytest.MonkeyPatch,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    minari = pytest.importorskip("minari")
    out = tmp_path / "minari"
    monkeypatch.chdir(tmp_path)  # a relative --out, as a user gives it
    code, stdout, err = run_cli(["export", data, "--to", "minari", "--out", "minari", "--name",
                                 "Synthetic Run", "--no-progress"], capsys)
    assert code == 0, err
    assert "sc2data/synthetic-run-v0" in stdout
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(out))
    dataset = minari.load_dataset("sc2data/synthetic-run-v0")
    assert dataset.total_episodes == EPISODES and dataset.total_steps == EPISODES * STEPS
    assert dataset.spec.action_space["function"].n > 500
    episodes = list(dataset.iterate_episodes())
    for ep, want in zip(episodes, expected(data), strict=True):
        for k, v in want["frames"].items():  # type: ignore[attr-defined]
            got = nested_get(ep.observations, k)
            assert got.dtype == v.dtype and np.array_equal(got, v), k
        assert np.array_equal(ep.actions["function"], want["function"])
        assert np.array_equal(ep.actions["args"], want["args"])
        assert np.array_equal(ep.rewards, want["reward"])
        assert ep.terminations.tolist() == [False] * (STEPS - 1) + [True]
        assert not ep.truncations.any()
        assert np.array_equal(ep.infos["available_actions"], want["masks"])


def test_hf_reads_back_with_datasets(data: Path, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    datasets = pytest.importorskip("datasets")
    out = tmp_path / "hf"
    code, stdout, err = run_cli(["export", data, "--to", "hf", "--out", out, "--no-progress"],
                                capsys)
    assert code == 0, err
    rows = datasets.load_from_disk(str(out / "dataset")).with_format("numpy")
    assert len(rows) == EPISODES * STEPS
    assert json.loads(rows.info.description)["episodes"] == EPISODES
    assert rows["episode"][0] == 0 and rows["step"][STEPS - 1] == STEPS - 1
    for i, ep in enumerate(expected(data)):
        mine = rows[i * STEPS:(i + 1) * STEPS]  # rows in (episode, step) order: one batch
        assert (np.asarray(mine["episode"]) == ep["id"]).all()
        assert np.asarray(mine["step"]).tolist() == list(range(STEPS))
        for k, v in ep["frames"].items():  # type: ignore[attr-defined]
            stored = rows.features[hf_column("observation", k)]  # numpy format widens ints
            assert getattr(stored, "dtype", getattr(stored, "feature", None)) in (
                v.dtype.name, datasets.Value(v.dtype.name)), k
            now = np.asarray(mine[hf_column("observation", k)])
            after = np.asarray(mine[hf_column("next_observation", k)])
            assert np.array_equal(now, v[:-1]) and np.array_equal(after, v[1:]), k
        assert np.array_equal(mine["function"], ep["function"])
        assert np.array_equal(mine["args"], ep["args"])
        assert np.array_equal(mine["reward"], ep["reward"])
        assert np.asarray(mine["terminated"]).tolist() == [False] * (STEPS - 1) + [True]
        assert not np.asarray(mine["truncated"]).any()
        assert np.array_equal(mine["available_actions"], ep["masks"][:-1])
        assert np.array_equal(mine["next_available_actions"], ep["masks"][1:])


def test_a_cut_episode_is_truncated_not_terminated(cut: Path, tmp_path: Path) -> None:
    from sc2data.data.export import export

    export(cut, "npz", tmp_path / "npz", progress=False)
    with np.load(tmp_path / "npz" / "episode-000000.npz") as z:
        assert len(z["rewards"]) == STEPS - 5
        assert not z["terminations"].any() and z["truncations"].tolist()[-1]


def test_bad_input_is_one_line_and_writes_nothing(data: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    code, _, err = run_cli(["export", data, "--to", "parquet", "--out", out], capsys)
    assert_one_line_error(code, err, "unknown export format 'parquet'", "npz, minari, hf")
    code, _, err = run_cli(["export", tmp_path / "nothing", "--to", "npz", "--out", out], capsys)
    assert_one_line_error(code, err, "nothing")
    assert not out.exists()
    out.mkdir()
    code, _, err = run_cli(["export", data, "--to", "npz", "--out", out], capsys)
    assert_one_line_error(code, err, "exists", "--overwrite")
    code, _, err = run_cli(["export", data, "--to", "npz", "--out", out, "--overwrite",
                            "--no-progress"], capsys)
    assert code == 0, err
    assert (out / "metadata.json").is_file()
    assert list(tmp_path.iterdir()) == [out]  # nothing beside it


def test_a_missing_package_names_the_extra(data: Path, tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    for module, to in (("minari", "minari"), ("datasets", "hf")):
        monkeypatch.setitem(sys.modules, module, None)  # import fails as if absent
        code, _, err = run_cli(["export", data, "--to", to, "--out", tmp_path / to], capsys)
        assert_one_line_error(code, err, repr(module), "pip install 'sc2data[export]'")
        assert not (tmp_path / to).exists()


def test_an_interrupted_export_leaves_nothing(data: Path, tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    from sc2data.data import export as mod

    real = mod.episode
    calls = []

    def interrupted(*args: object, **kw: object) -> object:
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(mod, "episode", interrupted)
    for to in ("npz", "hf"):
        calls.clear()
        with pytest.raises(KeyboardInterrupt):
            mod.export(data, to, tmp_path / to, progress=False)
        assert list(tmp_path.iterdir()) == [], to


def test_a_dataset_without_masks_exports_without_them(tmp_path: Path) -> None:
    """A dataset written before action masks were kept (format 3) exports as before."""
    pytest.importorskip("datasets")
    import datasets

    from sc2data.data.export import export
    from tests.synthetic_data import as_format

    old = tmp_path / "old"
    make_dataset(old, episodes=1)
    as_format(old, 3)
    export(old, "npz", tmp_path / "npz", progress=False)
    with np.load(tmp_path / "npz" / "episode-000000.npz") as z:
        assert "available_actions" not in z.files and len(z["rewards"]) == STEPS
    meta = json.loads((tmp_path / "npz" / "metadata.json").read_text())
    assert meta["available_actions"].startswith("not kept")
    export(old, "hf", tmp_path / "hf", progress=False)
    rows = datasets.load_from_disk(str(tmp_path / "hf" / "dataset"))
    assert "available_actions" not in rows.column_names and len(rows) == STEPS


def test_a_rerun_after_a_kill_finishes_and_leaves_nothing_beside_out(
        data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """What a ``kill -9`` leaves, at any moment, is no obstacle to the same command: a half-made
    ``OUT.PID.partial`` (or the ``OUT.old.PID.partial`` of an ``--overwrite``) of a process that
    no longer runs is removed (it used to stay beside ``--out`` for good), one of a running
    export is left to it; and an ``OUT`` that is already this export (the kill landed after the
    rename) is exported again, where any other ``OUT`` is still refused (issue 31)."""
    import subprocess

    out = tmp_path / "npz"
    gone = subprocess.Popen(["true"])
    gone.wait()
    for stale in (f"npz.{gone.pid}.partial", f"npz.old.{gone.pid}.partial"):
        (tmp_path / stale).mkdir()
        (tmp_path / stale / "episode-000000.npz").write_bytes(b"half")
    live = tmp_path / f"npz.{os.getppid()}.partial"  # a running export's: not ours to remove
    live.mkdir()
    argv = ["export", data, "--to", "npz", "--out", out, "--no-progress"]
    code, _, err = run_cli(argv, capsys)
    assert code == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["npz", live.name])
    live.rmdir()
    first = {p.name: p.read_bytes() for p in out.iterdir()}
    code, _, err = run_cli(argv, capsys)  # OUT is this export: made again, not refused
    assert code == 0, err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == first
    assert list(tmp_path.iterdir()) == [out]
    code, _, err = run_cli([*argv, "--episodes", "1"], capsys)  # another export: refused
    assert_one_line_error(code, err, "exists", "--overwrite")
    (out / "metadata.json").write_text("[]")
    code, _, err = run_cli(argv, capsys)
    assert_one_line_error(code, err, "exists", "--overwrite")
    assert list(tmp_path.iterdir()) == [out]
