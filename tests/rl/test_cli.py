"""``sc2data rl`` as a user runs it: train, resume, evaluate, plot, and one-line errors."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from sc2data.rl.runs import read_curve
from tests.cli import assert_one_line_error, run_cli

TINY = ["--steps", "96", "--envs", "1", "--rollout", "32", "--batch-size", "32",
        "--episode-steps", "40",
        "--checkpoint-every", "64", "--no-progress"]


def test_train_resume_evaluate_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    code, out, err = run_cli(["rl", "train", "--out", run, "--seed", "1", *TINY], capsys)
    assert code == 0, err
    state = json.loads((run / "state.json").read_text())
    assert state["timesteps"] == 96 and state["resumes"] == 0
    header, *rows = (run / "curve.csv").read_text().splitlines()
    assert header == "episode,env,timesteps,env_steps,marines,game_return,return"
    assert rows and all(int(r.split(",")[3]) % 40 == 0 for r in rows)  # episodes of 40 steps
    # Rerunning the same command does nothing; a larger --steps continues from the checkpoint.
    code, out, err = run_cli(["rl", "train", "--out", run, "--seed", "1", *TINY], capsys)
    assert code == 0 and "already trained" in out
    more = [a if a != "96" else "160" for a in TINY]
    code, out, err = run_cli(["rl", "train", "--out", run, "--seed", "1", *more], capsys)
    assert code == 0, err
    state = json.loads((run / "state.json").read_text())
    assert state["timesteps"] == 160 and state["resumes"] == 1
    assert len((run / "curve.csv").read_text().splitlines()) > len(rows) + 1
    # Other settings in the same folder: refused, nothing changed.
    code, _, err = run_cli(["rl", "train", "--out", run, "--seed", "2", *more], capsys)
    assert_one_line_error(code, err, "other settings", "seed")

    code, out, err = run_cli(["rl", "evaluate", run, "--episodes", "2", "--no-progress"], capsys)
    assert code == 0, err
    assert "sampled: marines per episode" in out and "argmax: marines per episode" in out
    assert "1 west, 1 east" in out
    result = json.loads((run / "eval.json").read_text())
    assert result["episodes"] == 2 and result["sides"] == ["west", "east"]
    assert all(s >= 1_000_000 for s in result["seeds"]) and result["trained_timesteps"] == 160
    for mode in ("sampled", "argmax"):
        assert len(result[mode]["marines"]) == 2
        assert result[mode]["mean"] == sum(result[mode]["marines"]) / 2
    # Sampled play is seeded per episode: the same figures again; one file holds both.
    code, out, err = run_cli(["rl", "evaluate", run, "--episodes", "2", "--no-progress"], capsys)
    assert code == 0, err
    assert json.loads((run / "eval.json").read_text()) == result
    assert not (run / "eval-stochastic.json").exists()
    # Spread over worker processes (the default here: one per core) or played in this one:
    # the same figures.
    code, out, err = run_cli(["rl", "evaluate", run, "--episodes", "2", "--processes", "1",
                              "--no-progress"], capsys)
    assert code == 0, err
    assert json.loads((run / "eval.json").read_text()) == result
    code, _, err = run_cli(["rl", "evaluate", run, "--processes", "0"], capsys)
    assert_one_line_error(code, err, "--processes must be at least 1")

    png = tmp_path / "curves.png"
    code, out, err = run_cli(["rl", "plot", run, run, "--window", "1000", "--out", png], capsys)
    assert code == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # Fewer episodes than the window: drawn as points, and said so.
    assert out.count("fewer than --window 1000: drawn as points") == 2
    code, out, err = run_cli(["rl", "plot", run, "--window", "2", "--out", png], capsys)
    assert code == 0 and "fewer than" not in out
    grouped = tmp_path / "grouped.png"
    code, out, err = run_cli(["rl", "plot", run, run, "--group", "--window", "1000", "--out",
                              grouped], capsys)
    assert code == 0, err
    assert grouped.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "drawn as points" in out
    assert grouped.read_bytes() != png.read_bytes()  # one mean line, not two run lines

    # One run is a group of one: compare reports its IQM and curve.
    code, out, err = run_cli(["rl", "compare", run, "--reps", "50", "--out", tmp_path / "c"],
                             capsys)
    assert code == 0, err
    assert "macro, sparse: 1 run, sampled IQM" in out
    assert (tmp_path / "c" / "compare.png").is_file()


def test_narration_training_with_a_tiny_mem(mem_run: Path, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "nar"
    code, _, err = run_cli(["rl", "train", "--out", run, "--reward", "narration", "--mem",
                            mem_run, "--action-space", "paper", "--threshold", "2", *TINY],
                           capsys)
    assert code == 0, err
    rows = (run / "curve.csv").read_text().splitlines()[1:]
    assert rows
    # game_return is the game's score alone; return adds the narration bonus.
    for r in rows:
        _, _, _, _, marines, game, shaped = r.split(",")
        assert float(game) == float(marines) and float(shaped) >= float(game)


@pytest.mark.parametrize("args, needles", [
    (["--action-space", "full"], ("unknown action space", "macro")),
    (["--reward", "dense"], ("unknown reward", "narration")),
    (["--reward", "narration"], ("--mem",)),
    (["--reward", "narration", "--mem", "/nonexistent/run"], ("does not exist",)),
    (["--steps", "0"], ("--steps",)),
    (["--obs", "pixels"], ("unknown obs", "compact")),
    (["--obs-size", "48"], ("--obs-size",)),
    (["--processes", "-1"], ("--processes",)),
    (["--env-groups", "0"], ("--env-groups", "at least 1")),
    (["--macro-sites", "near"], ("unknown macro sites 'near'", "far")),
    (["--action-space", "paper", "--macro-sites", "far"], ("--macro-sites", "macro")),
    (["--obs", "stored", "--history"], ("--history", "--obs compact")),
    (["--action-space", "paper", "--no-share-features"], ("--no-share-features", "spatial")),
    (["--action-space", "paper", "--point-head", "subpixel"], ("unknown point head", "pixel")),
    (["--point-head", "pixel"], ("--point-head pixel", "spatial")),
    (["--threads", "0"], ("--threads",)),
    (["--device", "tpu"], ("unknown device", "cuda")),
    (["--reward", "rules", "--bonus", "nan"], ("--bonus", "finite")),
    (["--reward", "rules", "--bonus", "inf"], ("--bonus", "finite")),
    (["--threshold", "nan"], ("--threshold",)),
    (["--threshold", "0"], ("--threshold",)),
    (["--normalize-advantage", "--batch-size", "1"], ("--normalize-advantage",)),
    (["--patience", "-1"], ("--patience",)),
    (["--learning-rate", "0"], ("--learning-rate", "positive")),
    (["--learning-rate", "nan"], ("--learning-rate", "positive")),
    (["--ent-coef-final", "-0.01"], ("--ent-coef-final", "0 or more")),
    (["--ent-coef-final", "inf"], ("--ent-coef-final", "finite")),
    (["--mem", "x"], ("--reward narration",)),
    (["--reward-scale", "0"], ("--reward-scale", "positive")),
    (["--reward-scale", "nan"], ("--reward-scale", "positive")),
    (["--vf-coef", "0"], ("--vf-coef", "positive")),
    (["--max-grad-norm", "-1"], ("--max-grad-norm", "positive")),
    (["--max-grad-norm", "inf"], ("--max-grad-norm", "positive")),
    (["--shaping", "dense"], ("unknown shaping", "potential")),
    (["--shaping", "potential"], ("--shaping potential", "--reward rules or narration")),
])
def test_bad_input_is_one_line_and_writes_nothing(
        args: list[str], needles: tuple[str, ...], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    code, _, err = run_cli(["rl", "train", "--out", run, *TINY, *args], capsys)
    assert_one_line_error(code, err, *needles)
    assert not run.exists()


def test_bad_narrations_are_one_line(mem_run: Path, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    empty, odd = tmp_path / "empty.txt", tmp_path / "odd.txt"
    empty.write_text("# nothing here\n")
    odd.write_text("build an SCV\nbuild a zorglubium\n")
    for narration, needles in ((empty, ("no command",)), (odd, ("zorglubium", "vocabulary"))):
        run = tmp_path / "run"
        code, _, err = run_cli(["rl", "train", "--out", run, "--reward", "narration", "--mem",
                                mem_run, "--narration", narration, *TINY], capsys)
        assert_one_line_error(code, err, *needles)
        assert not run.exists()


def test_evaluate_and_plot_refuse_what_is_not_a_run(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["rl", "evaluate", tmp_path], capsys)
    assert_one_line_error(code, err, "not a trained sc2data rl run")
    code, _, err = run_cli(["rl", "plot", tmp_path, "--out", tmp_path / "x.png"], capsys)
    assert_one_line_error(code, err, "not an sc2data rl run")
    assert not (tmp_path / "x.png").exists()


def test_an_out_file_that_is_a_folder_or_under_a_file_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``rl plot --out`` and ``rl agreement --out`` take a file name: a folder there, or a file
    above it, is one line before any work (were tracebacks once the work was done)."""
    (tmp_path / "afile").write_text("")
    for out, needle in ((tmp_path, "it is a folder"), (tmp_path / "afile" / "x", "is a file")):
        for argv in (["rl", "plot", tmp_path, "--out", out],
                     ["rl", "agreement", tmp_path, "--mem", tmp_path, "--out", out]):
            code, _, err = run_cli(argv, capsys)
            assert_one_line_error(code, err, f"cannot write {out}", needle)


def test_missing_extra_names_the_install(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "sb3_contrib", None)  # import sb3_contrib → ImportError
    code, _, err = run_cli(["rl", "train", "--out", tmp_path / "run", *TINY], capsys)
    assert_one_line_error(code, err, "sb3-contrib", "pip install 'sc2data[rl]'")
    assert not (tmp_path / "run").exists()


def test_agreement_counts_add_up_and_follow_the_threshold(
        mem_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    code, _, err = run_cli(["rl", "train", "--out", run, *TINY], capsys)
    assert code == 0, err
    results = {}
    for threshold, progress in (("0", "--no-progress"), ("100", "--progress")):
        out = tmp_path / f"agree-{threshold}.json"
        code, text, err = run_cli(["rl", "agreement", run, "--mem", mem_run, "--episodes", "1",
                                   "--threshold", threshold, "--out", out, progress], capsys)
        assert code == 0, err
        assert ("rl agreement" in err) == (progress == "--progress")  # the episodes' bar
        assert "precision" in text and "build_scv" in text
        results[threshold] = json.loads(out.read_text())
    never, always = results["0"], results["100"]
    assert never["stacks"] == always["stacks"] == 40  # one 40-step episode, one stack a step
    for cid, c in always["commands"].items():
        # The rules do not depend on the threshold; the MEM matches everything or nothing.
        assert c["rule_fired"] == never["commands"][cid]["rule_fired"]
        assert c["tp"] + c["fn"] == c["rule_fired"] and c["tp"] + c["fp"] == c["mem_matched"]
        assert c["mem_matched"] == 40 and never["commands"][cid]["mem_matched"] == 0
        assert c["recall"] == (1.0 if c["rule_fired"] else None)
        assert never["commands"][cid]["precision"] is None
    assert always["null_unmatched"] in (0.0, None) and never["null_unmatched"] in (1.0, None)
    assert sum(c["rule_fired"] for c in always["commands"].values()) > 0  # collect_minerals
    code, _, err = run_cli(["rl", "agreement", run, "--mem", tmp_path / "nope"], capsys)
    assert_one_line_error(code, err, "does not exist")
    code, _, err = run_cli(["rl", "agreement", tmp_path, "--mem", mem_run], capsys)
    assert_one_line_error(code, err, "not a trained sc2data rl run")


def test_seed_band_spans_the_episodes_every_run_reached() -> None:
    import numpy as np

    from sc2data.rl import train
    from sc2data.rl.evaluate import play, seed_band

    assert train.seed_band is seed_band and train.play is play  # the old names still import

    a = (np.array([10.0, 20.0, 30.0]), np.array([1.0, 4.0, 9.0]))
    b = (np.array([12.0, 22.0]), np.array([3.0, 2.0]))
    xs, mean, lo, hi = seed_band([a, b])
    assert xs.tolist() == [11.0, 21.0]
    assert mean.tolist() == [2.0, 3.0] and lo.tolist() == [1.0, 2.0] and hi.tolist() == [3.0, 4.0]


def test_cuda_without_a_gpu_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import torch

    if torch.cuda.is_available():
        pytest.skip("a CUDA GPU is present here")
    run = tmp_path / "run"
    code, _, err = run_cli(["rl", "train", "--out", run, *TINY, "--device", "cuda"], capsys)
    assert_one_line_error(code, err, "--device cuda", "no CUDA GPU")
    assert not run.exists()


def test_separate_feature_networks_train_and_evaluate(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """``--no-share-features``: the policy and the value function each get their own feature
    network, recorded in the run's config; the run evaluates like any other. ``--vf-coef`` and
    ``--max-grad-norm`` reach PPO and the record too."""
    run = tmp_path / "run"
    code, _, err = run_cli(["rl", "train", "--out", run, "--no-share-features",
                            "--vf-coef", "0.25", "--max-grad-norm", "2", *TINY], capsys)
    assert code == 0, err
    config = json.loads((run / "config.json").read_text())
    assert (config["share_features"], config["vf_coef"], config["max_grad_norm"]) == (
        False, 0.25, 2.0)
    from sb3_contrib import MaskablePPO

    model = MaskablePPO.load(run / "model.zip", device="cpu")
    assert (model.vf_coef, model.max_grad_norm) == (0.25, 2.0)
    policy = model.policy
    assert policy.pi_features_extractor is not policy.vf_features_extractor
    code, _, err = run_cli(["rl", "evaluate", run, "--episodes", "1", "--no-progress"], capsys)
    assert code == 0, err


def test_a_scaled_reward_keeps_the_records_in_the_games_units(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--reward-scale``: PPO learns from the scaled reward, while the curve records the game's
    marines and the unscaled return — before the first update the same seed plays the same
    episodes whatever the scale, so their rows are equal."""
    rows = {}
    for scale in ("1", "0.01"):
        run = tmp_path / scale
        code, _, err = run_cli(["rl", "train", "--out", run, "--reward", "rules",
                                "--shaping", "event", "--envs", "2", "--rollout", "64",
                                "--steps", "128", "--episode-steps", "60", "--processes", "0",
                                "--reward-scale", scale, "--no-progress"], capsys)
        assert code == 0, err
        assert json.loads((run / "config.json").read_text())["reward_scale"] == float(scale)
        rows[scale] = [r for r in read_curve(run) if r["timesteps"] <= 128]
    assert rows["1"] and len(rows["1"]) == len(rows["0.01"])
    for a, b in zip(rows["1"], rows["0.01"]):
        assert a == pytest.approx(b, abs=1e-4)
    assert any(r["return"] != r["game_return"] for r in rows["1"])  # the bonus is in "return"
