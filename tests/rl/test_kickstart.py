"""``rl train --kickstart RUN``: after each PPO update, a pass that pulls the policy towards a
teacher's (KL(teacher ‖ policy) on the rollout's states, under its masks)."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from sc2data.rl import runs
from sc2data.rl.pipeline import masked_kl
from tests.cli import assert_one_line_error, run_cli

TINY = ["--steps", "64", "--envs", "2", "--rollout", "16", "--batch-size", "32",
        "--episode-steps", "20", "--checkpoint-every", "32", "--no-progress"]


@pytest.fixture(scope="module")
def teacher(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A policy far from a fresh one: trained with a large step and no entropy bonus."""
    from tests.cli import exit_code

    run = tmp_path_factory.mktemp("rl") / "teacher"
    assert exit_code("rl", "train", "--out", run, *TINY, "--reward", "rules",
                     "--learning-rate", "0.01", "--ent-coef", "0", "--seed", "7") == 0
    return run


@pytest.fixture(scope="module")
def paper_teacher(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same in pysc2's action space, with the spatial policy."""
    from tests.cli import exit_code

    run = tmp_path_factory.mktemp("rl") / "paper-teacher"
    assert exit_code("rl", "train", "--out", run, *TINY, "--action-space", "paper",
                     "--reward", "rules", "--learning-rate", "0.01", "--ent-coef", "0",
                     "--seed", "7") == 0
    return run


def _kl_to(teacher: Path, run: Path) -> float:
    """Mean KL(teacher ‖ run's policy) over the states of a few random macro decisions."""
    from sc2data.rl.train import load_config, make_vec_env

    cfg = load_config(run)
    vec = make_vec_env(cfg)
    try:
        t = runs.load_model(teacher, vec).policy
        s = runs.load_model(run, vec).policy
        obs, kls = vec.reset(), []
        rng = np.random.default_rng(0)
        for _ in range(12):
            masks = vec.action_masks()
            with torch.no_grad():
                o = {k: torch.as_tensor(v) for k, v in obs.items()}
                kls.append(masked_kl(t.get_distribution(o, masks),
                                     s.get_distribution(o, masks)).mean().item())
            if cfg.action_space == "paper":  # an allowed function, anywhere on the screen
                acts = [[rng.choice(np.flatnonzero(m[:-128])), *rng.integers(64, size=2)]
                        for m in masks]
            else:
                acts = [rng.choice(np.flatnonzero(m)) for m in masks]
            obs, *_ = vec.step(np.array(acts))
    finally:
        vec.close()
    return float(np.mean(kls))


def test_masked_kl_by_hand() -> None:
    from sb3_contrib.common.maskable.distributions import MaskableCategoricalDistribution

    def dist(logits: list[float], mask: list[bool]) -> MaskableCategoricalDistribution:
        d = MaskableCategoricalDistribution(len(logits)).proba_distribution(
            torch.tensor([logits]))
        d.apply_masking(np.array([mask]))
        return d

    mask = [True, True, False]
    p, q = dist([0.0, 0.0, 5.0], mask), dist([np.log(3.0), 0.0, -5.0], mask)
    # p = (1/2, 1/2) and q = (3/4, 1/4) on the allowed actions; the masked third adds nothing
    want = 0.5 * np.log(0.5 / 0.75) + 0.5 * np.log(0.5 / 0.25)
    assert masked_kl(p, q).item() == pytest.approx(want, rel=1e-5)
    assert masked_kl(p, p).item() == pytest.approx(0.0, abs=1e-7)


def test_the_spatial_kl_sums_over_every_function_and_pixel() -> None:
    """The paper policy's joint KL against Σ_a p(a) log p(a)/q(a) over every (function, x, y)
    by enumeration (a point function's 4,096 pixels, another function once), with one function
    masked in both."""
    from sc2data.rl.envs import PAPER_FUNCTIONS
    from sc2data.rl.spatial import POINT_FUNCTIONS, PointDistribution

    g = torch.Generator().manual_seed(1)
    n, side = len(PAPER_FUNCTIONS), 4
    logits = [(torch.randn(1, n, generator=g), torch.randn(1, len(POINT_FUNCTIONS), side * side,
                                                          generator=g)) for _ in range(2)]
    mask = np.ones((1, n + 128), dtype=bool)
    mask[0, PAPER_FUNCTIONS.index("Train_Marine_quick")] = False
    acts = [(f, x, y) for f, name in enumerate(PAPER_FUNCTIONS) if name != "Train_Marine_quick"
            for x, y in ([(x, y) for x in range(64) for y in range(64)]
                         if name in POINT_FUNCTIONS else [(0, 0)])]
    a = torch.tensor(acts)
    log = []
    for fn, pts in logits:
        d = PointDistribution(fn.expand(len(a), -1), pts.expand(len(a), -1, -1))
        d.apply_masking(np.repeat(mask, len(a), axis=0))
        log.append(d.log_prob(a))
    lp, lq = log
    assert torch.logsumexp(lp, 0).item() == pytest.approx(0.0, abs=1e-4)  # every action once
    want = (lp.exp() * (lp - lq)).sum().item()
    p, q = (PointDistribution(fn, pts) for fn, pts in logits)
    for d in (p, q):
        d.apply_masking(mask)
    assert masked_kl(p, q).item() == pytest.approx(want, rel=1e-4)
    assert masked_kl(p, p).item() == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("space", ["macro", "paper"])
def test_a_kickstarted_run_ends_nearer_its_teacher(
        space: str, request: pytest.FixtureRequest, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The same seed and settings with and without --kickstart: the kickstarted policy ends
    several times nearer the teacher's, logs the KL of each pass, and records the teacher by
    path and content — the macro space's independent policy and the paper space's spatial one."""
    teacher = request.getfixturevalue("teacher" if space == "macro" else "paper_teacher")
    kicked, plain = tmp_path / "kicked", tmp_path / "plain"
    common = [*TINY, "--seed", "3", "--learning-rate", "0.003", "--action-space", space]
    for run, extra in ((kicked, ["--kickstart", teacher, "--kickstart-coef", "5"]),
                       (plain, [])):
        code, _, err = run_cli(["rl", "train", "--out", run, *common, *extra], capsys)
        assert code == 0, err
    near, far = _kl_to(teacher, kicked), _kl_to(teacher, plain)
    assert near < 0.5 * far, (near, far)
    with open(kicked / runs.LOGS / "0" / "progress.csv") as f:
        logged = [float(r["train/kickstart_kl"]) for r in csv.DictReader(f)
                  if r.get("train/kickstart_kl")]
    assert logged and all(v >= 0 for v in logged)  # SB3 writes an update's log at the next
    config = json.loads((kicked / runs.CONFIG).read_text())
    assert config["kickstart"] == str(teacher) and config["kickstart_coef"] == 5.0
    assert config["inputs"]["kickstart_sha256"] == runs.sha256_file(teacher / runs.MODEL)
    assert json.loads((plain / runs.CONFIG).read_text())["kickstart"] is None


def test_a_kickstarted_run_resumes_with_its_teacher_only(
        teacher: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A resume needs the teacher it began with: gone or changed, one line, nothing written;
    a bad teacher at the start is one line and leaves no folder."""
    src = tmp_path / "teacher"
    shutil.copytree(teacher, src)
    run = tmp_path / "run"
    code, _, err = run_cli(["rl", "train", "--out", run, *TINY, "--kickstart", src], capsys)
    assert code == 0, err
    longer = [a if a != "64" else "96" for a in TINY]
    before = (run / runs.MODEL).read_bytes()
    (src / runs.MODEL).write_bytes((src / runs.MODEL).read_bytes() + b"\0")
    code, _, err = run_cli(["rl", "train", "--out", run, *longer, "--kickstart", src], capsys)
    assert_one_line_error(code, err, "another kickstart")
    shutil.rmtree(src)
    code, _, err = run_cli(["rl", "train", "--out", run, *longer, "--kickstart", src], capsys)
    assert_one_line_error(code, err, "--kickstart", "not a trained")
    assert (run / runs.MODEL).read_bytes() == before
    for extra, needles in (
            (["--kickstart", tmp_path / "nothing"], ("--kickstart", "not a trained")),
            (["--kickstart", teacher, "--history"], ("--history False", "a teacher needs")),
            (["--kickstart", teacher, "--action-space", "paper"],
             ("--action-space macro", "a teacher needs")),
            (["--kickstart", teacher, "--kickstart-coef", "0"], ("--kickstart-coef",))):
        out_dir = tmp_path / "bad"
        code, _, err = run_cli(["rl", "train", "--out", out_dir, *TINY, *extra], capsys)
        assert_one_line_error(code, err, *needles)
        assert not out_dir.exists()


def test_a_teacher_may_have_another_network(
        teacher: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The teacher shares the run's inputs and outputs only: one feature network each in the
    student, a shared one in the teacher."""
    run = tmp_path / "run"
    code, _, err = run_cli(["rl", "train", "--out", run, *TINY, "--no-share-features",
                            "--kickstart", teacher], capsys)
    assert code == 0, err
    assert runs.read_state(run)["timesteps"] == 64
