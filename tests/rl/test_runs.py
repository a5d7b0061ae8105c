"""An RL run is a folder like the others: locked while written, its inputs and files checked by
content, a checkpoint committed whole, SB3's logs written."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from sc2data.ground.files import FolderLock
from sc2data.rl import runs
from tests.cli import assert_one_line_error, run_cli

TINY = ["--steps", "64", "--envs", "2", "--rollout", "16", "--batch-size", "32",
        "--episode-steps", "20", "--checkpoint-every", "32", "--no-progress"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run = tmp_path_factory.mktemp("rl") / "run"
    code = _cli(["rl", "train", "--out", run, *TINY])
    assert code == 0
    return run


def _cli(argv: list[object]) -> int:
    from tests.cli import exit_code

    return exit_code(*argv)


def _copy(run: Path, to: Path) -> Path:
    shutil.copytree(run, to)
    return to


def test_a_run_writes_logs_a_summary_and_a_checked_checkpoint(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    code, out, err = run_cli(["rl", "train", "--out", run, *TINY], capsys)
    assert code == 0, err
    assert out.startswith(f"trained {run}: 64 decisions") and "marines on average" in out
    state = json.loads((run / runs.STATE).read_text())
    assert len(state["model_sha256"]) == 64 and len(state["curve_sha256"]) == 64
    with (run / runs.LOGS / "0" / "progress.csv").open() as f:
        header = next(csv.reader(f))
    for column in ("train/approx_kl", "train/entropy_loss", "train/clip_fraction",
                   "train/explained_variance", "train/value_loss", "game/marines_mean"):
        assert column in header
    assert not list(run.glob("*.partial*"))


def test_a_resumed_runs_speed_counts_only_the_decisions_it_trained(
        trained: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import re

    from sc2data.rl.train import summary_line, trained_steps

    run = _copy(trained, tmp_path / "run")
    before = trained_steps(run)
    assert before > 0 and trained_steps(tmp_path / "none") == 0
    assert "; 1 decisions/s" in summary_line(run, before / 2, since=before // 2)
    assert "; 2 decisions/s" in summary_line(run, before / 2)
    assert "decisions/s" not in summary_line(run, 1.0, since=before)  # nothing trained
    code, out, err = run_cli(["rl", "train", "--out", run, *TINY, "--steps", str(before + 64)],
                             capsys)
    assert code == 0, err
    rate = float(re.search(r"; ([\d,]+) decisions/s this session", out)[1].replace(",", ""))
    assert rate < 5_000, out  # 64 decisions in a real session, not the run's total


def test_two_trainings_into_one_folder_cannot_both_write(
        trained: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = _copy(trained, tmp_path / "run")
    with FolderLock(run, "rl train"):
        code, _, err = run_cli(["rl", "train", "--out", run, *TINY, "--steps", "96"], capsys)
    assert_one_line_error(code, err, "another sc2data rl train is writing", str(run))


@pytest.mark.parametrize("damage, needles", [
    ("model", ("model.zip", "not the model")),
    ("curve", ("curve.csv", "not the curve")),
    ("state", ("no state.json",)),
])
def test_files_not_of_the_last_checkpoint_are_refused(
        trained: Path, tmp_path: Path, damage: str, needles: tuple[str, ...],
        capsys: pytest.CaptureFixture[str]) -> None:
    run = _copy(trained, tmp_path / "run")
    if damage == "model":
        data = bytearray((run / runs.MODEL).read_bytes())
        data[len(data) // 2] ^= 1
        (run / runs.MODEL).write_bytes(bytes(data))
    elif damage == "curve":
        with (run / runs.CURVE_CSV).open("a") as f:
            f.write("99,0,1,1,500,500,500\n")
    else:
        (run / runs.STATE).unlink()
    for argv in (["rl", "train", "--out", run, *TINY, "--steps", "96"],
                 ["rl", "evaluate", run, "--episodes", "1", "--no-progress"],
                 ["rl", "plot", run, "--out", tmp_path / "c.png"]):
        if damage == "model" and argv[1] == "plot":
            continue  # a plot reads the curve, not the model
        code, _, err = run_cli(argv, capsys)
        assert_one_line_error(code, err, *needles)
    assert not (tmp_path / "c.png").exists()


def test_a_model_of_another_action_space_is_refused_though_recorded(
        trained: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A paper-space model.zip put into a macro run with its sha256 recorded (a run written
    before the sha256 were, or a hand-made one) is one line where it is loaded, not a tensor
    shape error from inside the policy."""
    paper = tmp_path / "paper"
    code, _, err = run_cli(["rl", "train", "--out", paper, *TINY, "--action-space", "paper",
                            "--steps", "32"], capsys)
    assert code == 0, err
    run = _copy(trained, tmp_path / "run")
    shutil.copy(paper / runs.MODEL, run / runs.MODEL)
    state = json.loads((run / runs.STATE).read_text())
    state["model_sha256"] = runs.sha256_file(run / runs.MODEL)
    (run / runs.STATE).write_text(json.dumps(state))
    for argv in (["rl", "train", "--out", run, *TINY, "--steps", "96"],
                 ["rl", "evaluate", run, "--episodes", "1", "--no-progress"]):
        code, _, err = run_cli(argv, capsys)
        assert_one_line_error(code, err, str(run / runs.MODEL), "was trained for other",
                              "config.json's settings")
    assert json.loads((run / runs.STATE).read_text()) == state


def test_an_edited_narration_or_another_mem_is_refused_on_resume(
        mem_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    narration = tmp_path / "narration.txt"
    narration.write_text("build a supply depot\nbuild a barracks\n")
    args = ["--reward", "narration", "--mem", mem_run, "--narration", narration,
            "--threshold", "2", "--action-space", "paper", *TINY]
    run = tmp_path / "run"
    code, _, err = run_cli(["rl", "train", "--out", run, *args], capsys)
    assert code == 0, err
    narration.write_text("build a barracks\nbuild a supply depot\n")
    code, _, err = run_cli(["rl", "train", "--out", run, *args, "--steps", "96"], capsys)
    assert_one_line_error(code, err, "another narration", "changed")
    narration.write_text("build a supply depot\nbuild a barracks\n")
    code, _, err = run_cli(["rl", "train", "--out", run, *args, "--steps", "96"], capsys)
    assert code == 0, err


@pytest.mark.parametrize("stop_after", ["model", "curve", "state-partial", "model-renamed"])
def test_a_commit_stopped_anywhere_leaves_one_whole_checkpoint(
        trained: Path, tmp_path: Path, stop_after: str) -> None:
    """The steps of ``runs.commit`` done by hand up to a stop; :func:`runs.recover` then leaves
    the old checkpoint or the new one, its files agreeing with its state."""
    from sb3_contrib import MaskablePPO

    run = _copy(trained, tmp_path / "run")
    old = json.loads((run / runs.STATE).read_text())
    model = MaskablePPO.load(run / runs.MODEL, device="cpu")
    model.policy.action_net.bias.data += 1.0  # a different model
    rows = runs.read_curve(run) + [{"episode": 99, "env": 0, "timesteps": 128, "env_steps": 128,
                                    "marines": 3, "game_return": 3, "return": 3}]
    model.save(run / runs.MODEL_PARTIAL)
    if stop_after != "model":
        (run / runs.CURVE_PARTIAL).write_bytes(runs.curve_bytes(rows))
    if stop_after in ("state-partial", "model-renamed"):
        new = {**old, "timesteps": 128, "model_sha256": runs.sha256_file(run / runs.MODEL_PARTIAL),
               "curve_sha256": runs.sha256_file(run / runs.CURVE_PARTIAL)}
        runs.write_record(run / runs.STATE_PARTIAL, new)
    if stop_after == "model-renamed":
        (run / runs.MODEL_PARTIAL).replace(run / runs.MODEL)
    runs.recover(run)
    state = runs.read_state(run)  # raises unless model, curve and state agree
    assert state is not None
    assert state["timesteps"] == (128 if stop_after in ("state-partial", "model-renamed")
                                  else old["timesteps"])
    assert not list(run.glob("*.partial*"))


@pytest.mark.parametrize("out", ["file", "under-file"])
def test_an_out_that_is_or_lies_under_a_file_is_one_line(
        tmp_path: Path, out: str, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "f"
    f.write_text("x")
    target = f if out == "file" else f / "run"
    code, _, err = run_cli(["rl", "train", "--out", target, *TINY], capsys)
    assert_one_line_error(code, err, "file")
    assert f.read_text() == "x"


def test_a_run_that_fails_before_its_first_checkpoint_leaves_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Not even the config.json that would refuse the corrected command as other settings."""
    import sc2data.rl.train as rl_train

    def broken(*args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(rl_train, "make_vec_env", broken)
    run = tmp_path / "run"
    code, _, err = run_cli(["rl", "train", "--out", run, *TINY], capsys)
    assert_one_line_error(code, err, "No space left", "free some space")
    assert not run.exists()
    monkeypatch.undo()
    code, _, err = run_cli(["rl", "train", "--out", run, *TINY, "--seed", "5"], capsys)
    assert code == 0, err


def _logged(run: Path, column: str) -> list[float]:
    values: list[float] = []
    for log in sorted((run / runs.LOGS).glob("*/progress.csv")):
        with log.open() as f:
            values += [float(r[column]) for r in csv.DictReader(f) if r[column]]
    return values


def test_an_annealed_entropy_bonus_falls_linearly_to_its_final_value(
        tmp_path: Path, trained: Path) -> None:
    """--ent-coef-final: each update's bonus is linear in the decisions trained before it, from
    --ent-coef to the final value at --steps (a resume with more --steps draws the line anew);
    without it the bonus stays --ent-coef."""
    run = tmp_path / "run"
    anneal = ["--ent-coef", "0.04", "--ent-coef-final", "0"]
    assert _cli(["rl", "train", "--out", run, *TINY, *anneal]) == 0  # updates at 32 and 64
    assert _logged(run, "train/ent_coef") == pytest.approx([0.02, 0.0])
    longer = [a if a != "64" else "128" for a in TINY]
    assert _cli(["rl", "train", "--out", run, *longer, *anneal]) == 0  # at 96 and 128
    assert _logged(run, "train/ent_coef") == pytest.approx([0.02, 0.0, 0.01, 0.0])
    assert set(_logged(trained, "train/ent_coef")) == {0.01}


def test_the_learning_rate_reaches_ppo(tmp_path: Path, trained: Path) -> None:
    run = tmp_path / "run"
    assert _cli(["rl", "train", "--out", run, *TINY, "--learning-rate", "0.001"]) == 0
    assert set(_logged(run, "train/learning_rate")) == {0.001}
    assert set(_logged(trained, "train/learning_rate")) == {0.0003}


def test_a_run_can_start_from_another_runs_policy(
        trained: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """--init-policy: the new run's policy before its first update is the other run's, weight
    for weight (training skipped here so that the checkpoint holds the starting policy); a
    fresh run of the same seed is not; the start is recorded by path and by content."""
    import torch

    from sc2data.rl.pipeline import PipelinedPPO

    monkeypatch.setattr(PipelinedPPO, "learn", lambda self, **kwargs: self)
    start, fresh = tmp_path / "start", tmp_path / "fresh"
    for run, extra in ((start, ["--init-policy", str(trained)]), (fresh, [])):
        code, _, err = run_cli(["rl", "train", "--out", run, *TINY, "--seed", "3", *extra],
                               capsys)
        assert code == 0, err

    def weights(run: Path) -> dict[str, torch.Tensor]:
        return dict(PipelinedPPO.load(run / runs.MODEL).policy.state_dict())

    source, started, new = weights(trained), weights(start), weights(fresh)
    assert source.keys() == started.keys()
    assert all(torch.equal(source[k], started[k]) for k in source)
    assert not all(torch.equal(source[k], new[k]) for k in source)
    config = json.loads((start / runs.CONFIG).read_text())
    assert config["init_policy"] == str(trained)
    assert config["inputs"]["init_policy_sha256"] == runs.sha256_file(trained / runs.MODEL)
    assert json.loads((fresh / runs.CONFIG).read_text())["init_policy"] is None


def test_a_started_run_resumes_without_its_start_and_a_bad_start_is_one_line(
        trained: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = _copy(trained, tmp_path / "src")
    run = tmp_path / "run"
    code, _, err = run_cli(["rl", "train", "--out", run, *TINY, "--init-policy", src], capsys)
    assert code == 0, err
    shutil.rmtree(src)  # a resume loads its own checkpoint and keeps the recorded digest
    code, out, err = run_cli(["rl", "train", "--out", run, *TINY, "--steps", "96",
                              "--init-policy", src], capsys)
    assert code == 0, err
    assert out.startswith(f"trained {run}: 96 decisions")
    for extra, needles in (
            (["--init-policy", tmp_path / "nothing"], ("--init-policy", "not a trained")),
            (["--init-policy", trained, "--action-space", "paper"],
             ("--action-space macro", "this run has paper")),
            (["--init-policy", trained, "--no-share-features"],
             ("--share-features True", "this run has False")),
            (["--init-policy", trained, "--history"], ("--history False",))):
        out_dir = tmp_path / "bad"
        code, _, err = run_cli(["rl", "train", "--out", out_dir, *TINY, *extra], capsys)
        assert_one_line_error(code, err, *needles)
        assert not out_dir.exists()  # nothing half-written
