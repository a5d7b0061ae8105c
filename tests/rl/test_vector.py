"""The batched vector env: same games as SB3's DummyVecEnv, batched rewards equal to the per-game
wrappers, SB3 and gymnasium contracts, shared memory that never outlives its processes."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

from sc2data.ground.errors import Sc2DataError
from sc2data.rl import arena
from sc2data.rl.batched import make_shaping
from sc2data.rl.envs import PAPER_FUNCTIONS
from sc2data.rl.train import RLConfig, check_config, make_env, make_vec_env, policy_kwargs, train
from sc2data.rl.vector import BuildMarinesVecEnv, BuildMarinesVectorEnv, GameConfig

STEPS = 60
"""pysc2 steps per episode: several episodes end within a test."""


def _masked_actions(masks: np.ndarray, space: str, rng: np.random.Generator) -> np.ndarray:
    if space == "macro":
        return np.array([rng.choice(np.flatnonzero(m)) for m in masks])
    n = len(PAPER_FUNCTIONS)
    return np.array([[rng.choice(np.flatnonzero(m[:n])), *rng.integers(64, size=2)]
                     for m in masks])


@pytest.mark.parametrize("space, reward, processes, shaping", [
    ("macro", "sparse", 0, "event"), ("paper", "rules", 2, "event"),
    ("macro", "narration", 2, "event"), ("paper", "narration", 0, "event"),
    ("macro", "rules", 2, "potential"), ("paper", "narration", 0, "potential"),
    ("macro", "narration", 2, "potential")])
def test_same_games_and_rewards_as_the_per_game_wrappers(
        space: str, reward: str, processes: int, shaping: str, mem_run: Path) -> None:
    """Observations, masks, rewards (the bonus included, as an event or a potential), ends and
    infos equal those of DummyVecEnv over the per-game reward wrappers, step by step on the
    same seeds."""
    mem = str(mem_run) if reward == "narration" else None
    cfg = RLConfig(out="unused", action_space=space, reward=reward, episode_steps=STEPS,
                   mem=mem, threshold=2.0 if mem else 0.5, envs=3, processes=processes,
                   obs="stored" if space == "paper" else "compact", shaping=shaping,
                   gamma=0.97)
    narration, scorer = check_config(cfg)
    old = DummyVecEnv([lambda: make_env(cfg, scorer, narration) for _ in range(3)])
    new = make_vec_env(cfg, scorer, narration)
    rng = np.random.default_rng(0)
    bonuses, paid = 0.0, 0
    try:
        old.seed(7)
        new.seed(7)
        a, b = old.reset(), new.reset()
        assert a.keys() == b.keys() and all((a[k] == b[k]).all() for k in a)
        for t in range(150):
            masks = new.action_masks()
            assert (masks == np.stack(old.env_method("action_masks"))).all()
            acts = _masked_actions(masks, space, rng)
            a, ra, da, ia = old.step(acts)
            b, rb, db, ib = new.step(acts)
            assert all((a[k] == b[k]).all() for k in a), t
            assert (ra == rb).all() and (da == db).all(), t
            for x, y in zip(ia, ib):
                for k in ("game_reward", "shaping", "env_steps", "invalid", "game_loop",
                          "marines", "narration_index"):
                    assert x.get(k) == y.get(k), (t, k)
                if "terminal_observation" in x:
                    assert all((x["terminal_observation"][k] == y["terminal_observation"][k])
                               .all() for k in a)
            bonuses += float(sum(i["shaping"] for i in ib))
            paid += sum(i["shaping"] > 0 for i in ib)
    finally:
        old.close()
        new.close()
    if reward != "sparse":
        assert paid > 0  # the comparison saw the shaping pay
    if shaping == "potential":
        assert bonuses < 0  # and, as a potential, pay back by each episode's end


def test_vec_env_contract_and_a_short_maskable_ppo_run() -> None:
    """What SB3's VecEnv promises, checked as its own env checks do, then MaskablePPO on it."""
    from sb3_contrib import MaskablePPO

    cfg = RLConfig(out="unused", action_space="paper", envs=4, episode_steps=20, processes=2,
                   obs_size=32)
    vec = make_vec_env(cfg)
    try:
        vec.seed(0)
        obs = vec.reset()
        assert vec.observation_space.contains({k: v[0] for k, v in obs.items()})
        assert all(v.shape[0] == 4 for v in obs.values())
        ends = 0
        rng = np.random.default_rng(1)
        for _ in range(45):
            obs, rewards, dones, infos = vec.step(_masked_actions(vec.action_masks(), "paper",
                                                                  rng))
            assert rewards.shape == (4,) and rewards.dtype == np.float32
            assert dones.shape == (4,) and dones.dtype == bool and len(infos) == 4
            for i, info in enumerate(infos):
                assert set(info) >= {"game_reward", "env_steps", "marines"}
                assert ("terminal_observation" in info) == bool(dones[i])
                if dones[i]:
                    assert vec.observation_space.contains(info["terminal_observation"])
                    ends += 1
            assert all(vec.observation_space.contains({k: v[i] for k, v in obs.items()})
                       for i in range(4))
        assert ends == 8  # every game ended twice (20 steps each), and restarted
        model = MaskablePPO("MultiInputPolicy", vec, n_steps=16, batch_size=32, n_epochs=1,
                            seed=0, device="cpu", policy_kwargs=policy_kwargs(cfg))
        model.learn(64)
        assert model.num_timesteps == 64
    finally:
        vec.close()


def test_gymnasium_vector_api() -> None:
    env = BuildMarinesVectorEnv(GameConfig("macro", game_loops=8 * 20), 2, processes=0)
    try:
        obs, infos = env.reset(seed=3)
        assert env.observation_space.contains(obs)
        finals = 0
        for _ in range(40):
            masks = env.action_masks()
            obs, rewards, terminated, truncated, infos = env.step(
                [int(np.flatnonzero(m)[0]) for m in masks])
            assert rewards.shape == terminated.shape == truncated.shape == (2,)
            finals += int(infos.get("_final_obs", np.zeros(2, bool)).sum())
            assert env.observation_space.contains(obs)
        assert finals >= 2
    finally:
        env.close()


def test_same_seed_same_envs_same_curve_whatever_the_processes(tmp_path: Path) -> None:
    """One seed, one number of games: one learning curve, in this process or in workers."""
    common = dict(action_space="macro", steps=192, envs=3, rollout=32, batch_size=48,
                  episode_steps=30, checkpoint_every=10**6, progress=False, seed=4)
    train(RLConfig(out=str(tmp_path / "a"), processes=0, **common))  # type: ignore[arg-type]
    train(RLConfig(out=str(tmp_path / "b"), processes=2, **common))  # type: ignore[arg-type]
    a = (tmp_path / "a" / "curve.csv").read_text()
    assert a == (tmp_path / "b" / "curve.csv").read_text()
    assert len(a.splitlines()) > 3
    train(RLConfig(out=str(tmp_path / "c"), processes=2, **{**common, "seed": 5}))  # type: ignore[arg-type]
    assert (tmp_path / "c" / "curve.csv").read_text() != a


_HOLD = """
import sys, time
from sc2data.rl.vector import BuildMarinesVecEnv, GameConfig
if __name__ == "__main__":
    vec = BuildMarinesVecEnv(GameConfig("macro"), 2, processes=2)
    vec.reset()
    print(" ".join(str(p.pid) for p in vec._procs), vec.arena.path, flush=True)
    time.sleep(60)
"""


def _gone(pid: int, within: float = 15.0) -> bool:
    end = time.monotonic() + within
    while time.monotonic() < end:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        try:  # a zombie of ours: reap it
            if os.waitpid(pid, os.WNOHANG)[0] == pid:
                return True
        except ChildProcessError:
            pass
        time.sleep(0.1)
    return False


def test_kill_9_leaves_no_shared_memory_and_no_worker(tmp_path: Path) -> None:
    script = tmp_path / "hold.py"
    script.write_text(_HOLD)
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline().split()  # type: ignore[union-attr]
    workers, path = [int(p) for p in line[:-1]], Path(line[-1])
    assert len(workers) == 2
    assert not path.exists()  # unlinked once both workers mapped it
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert all(_gone(w) for w in workers)  # workers see the pipe close and end
    assert not list(arena.folder().glob(f"{arena.PREFIX}{proc.pid}-*"))


def _run_script(tmp_path: Path, text: str) -> subprocess.CompletedProcess[str]:
    """``text`` run as a script in a fresh interpreter (no resource tracker yet), with
    Ctrl-C's default disposition: an ignored SIGINT survives exec, and the pytest worker running
    this may have been left ignoring it by an earlier test (the script then saw no Ctrl-C and
    printed nothing, under ``-n 2`` and only in some orders)."""
    script = tmp_path / "script.py"
    script.write_text(text)
    return subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=120, cwd=Path(__file__).parents[2],
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


_MASKS = """
import signal
from multiprocessing import util
from sc2data.rl.vector import BuildMarinesVecEnv, GameConfig
spawn = util.spawnv_passfds
def recording(path, args, passfds):
    if any("spawn_main" in str(a) for a in args):  # a worker, not the resource tracker
        print("blocked" if signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, []) else
              "open", flush=True)
    return spawn(path, args, passfds)
util.spawnv_passfds = recording
if __name__ == "__main__":
    BuildMarinesVecEnv(GameConfig("macro"), 2, processes=2).close()
"""


def test_every_worker_starts_with_ctrl_c_blocked(tmp_path: Path) -> None:
    """In a fresh interpreter (no resource tracker yet): starting multiprocessing's tracker
    unblocks SIGINT, so a worker started after it could die of a Ctrl-C while it imports, with
    a traceback (seen in tests/test_interrupts.py under load)."""
    out = _run_script(tmp_path, _MASKS)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["blocked", "blocked"], out.stdout


_CTRL_C_MID_START = """
import os, signal, threading
from multiprocessing import util
from sc2data.rl.vector import BuildMarinesVecEnv, GameConfig
spawn = util.spawnv_passfds
def spawn_then_ctrl_c(path, args, passfds):
    pid = spawn(path, args, passfds)
    if any("spawn_main" in str(a) for a in args):  # a worker, its start-up data not yet sent
        sender = threading.Thread(target=os.kill, args=(os.getpid(), signal.SIGINT))
        sender.start()
        sender.join()  # the other thread's Ctrl-C is sent here, before the data is written
    return pid
util.spawnv_passfds = spawn_then_ctrl_c
if __name__ == "__main__":
    try:
        BuildMarinesVecEnv(GameConfig("macro"), 2, processes=2)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
"""


def test_a_ctrl_c_while_a_worker_starts_waits_for_its_start_up_data(tmp_path: Path) -> None:
    """A Ctrl-C received by another thread while a worker is being started is raised once the
    workers have their start-up data: the learner is interrupted, no worker prints a
    traceback (its half-written pipe: EOFError)."""
    out = _run_script(tmp_path, _CTRL_C_MID_START)
    assert out.stdout.split() == ["interrupted"], (out.stdout, out.stderr)
    assert "Traceback" not in out.stderr, out.stderr


def test_a_file_left_by_a_killed_start_is_swept(tmp_path: Path) -> None:
    """Killed between creating and unlinking its file (a moment at start-up): the next vector
    env removes the file of a creator that no longer runs, and only such files."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    stale = arena.folder() / f"{arena.PREFIX}{int(dead.stdout)}-deadbeef"
    live = arena.folder() / f"{arena.PREFIX}{os.getpid()}-cafecafe"
    stale.write_bytes(b"x" * 4096)
    live.write_bytes(b"x")
    try:
        vec = BuildMarinesVecEnv(GameConfig("macro"), 2, processes=1)
        vec.close()
        assert not stale.exists() and live.exists()
    finally:
        stale.unlink(missing_ok=True)
        live.unlink(missing_ok=True)


def test_a_worker_that_dies_is_one_line() -> None:
    vec = BuildMarinesVecEnv(GameConfig("macro", game_loops=8 * 20), 2, processes=2)
    try:
        vec.reset()
        vec._procs[1].kill()
        vec._procs[1].join()
        with pytest.raises(Sc2DataError, match="ended unexpectedly"):
            vec.step(np.array([5, 5]))
    finally:
        vec.close()


def test_settings_that_cannot_run_are_errors() -> None:
    with pytest.raises(Sc2DataError, match="--envs"):
        BuildMarinesVecEnv(GameConfig(), 0)
    with pytest.raises(Sc2DataError, match="--processes"):
        BuildMarinesVecEnv(GameConfig(), 2, processes=-1)
    with pytest.raises(Sc2DataError, match="unknown reward"):
        make_shaping("dense")


def test_reset_infos_and_json_friendly_infos() -> None:
    vec = BuildMarinesVecEnv(GameConfig("paper", game_loops=8 * 5), 2, processes=0)
    try:
        vec.seed(0)
        vec.reset()
        assert [i["marines"] for i in vec.reset_infos] == [0, 0]
        _, _, _, infos = vec.step(np.zeros((2, 3), dtype=int))
        json.dumps([{k: v for k, v in i.items() if k != "terminal_observation"} for i in infos])
    finally:
        vec.close()



def test_a_reward_that_reads_frames_keeps_the_games_settings(mem_run: Path) -> None:
    """The vector env adds the reward's frame schema to the game config; nothing else of it is
    lost on the way (merged waits, sites)."""
    cfg = RLConfig(out="unused", action_space="macro", reward="narration", mem=str(mem_run),
                   envs=1, processes=0, macro_sites="far", episode_steps=STEPS)
    narration, scorer = check_config(cfg)
    vec = make_vec_env(cfg, scorer, narration)
    try:
        assert vec.cfg.frames is not None
        assert vec.cfg.merge_waits and vec.cfg.sites == "far"
        assert vec.cfg.game_loops == STEPS * 8
    finally:
        vec.close()


def test_reward_scale_scales_what_the_learner_gets_and_nothing_else() -> None:
    """``reward_scale``: the rewards PPO reads are the game's and the bonus's times the scale;
    the games, their infos (the game's reward, the bonus) and observations do not change."""
    base = RLConfig(out="unused", reward="rules", shaping="event", episode_steps=STEPS, envs=2,
                    processes=0, obs="compact")
    envs = [make_vec_env(base), make_vec_env(dataclasses.replace(base, reward_scale=0.25))]
    rng = np.random.default_rng(0)
    paid = 0.0
    try:
        for env in envs:
            env.seed(3)
        a, b = (env.reset() for env in envs)
        for _ in range(120):
            acts = _masked_actions(envs[0].action_masks(), "macro", rng)
            a, ra, _, ia = envs[0].step(acts)
            b, rb, _, ib = envs[1].step(acts)
            assert all((a[k] == b[k]).all() for k in a)
            assert rb == pytest.approx(0.25 * ra)
            for x, y in zip(ia, ib):
                assert (x["game_reward"], x["shaping"]) == (y["game_reward"], y["shaping"])
            paid += float(np.abs(ra).sum())
    finally:
        for env in envs:
            env.close()
    assert paid > 0


@pytest.mark.parametrize("reward, cores, workers", [
    ("narration", 2, 1), ("sparse", 2, 2), ("narration", 1, 1), ("rules", 4, 4),
    ("narration", 4, 3)])
def test_a_mem_learner_keeps_a_core_of_its_own(reward: str, cores: int, workers: int,
                                               mem_run: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """By default one worker process per core, one fewer where a MEM scores the reward in the
    learner's process, never none."""
    monkeypatch.setattr(os, "sched_getaffinity", lambda _: set(range(cores)), raising=False)
    cfg = RLConfig(out="unused", action_space="paper", reward=reward, envs=8,
                   mem=str(mem_run) if reward == "narration" else None)
    narration, scorer = check_config(cfg)
    vec = make_vec_env(cfg, scorer, narration)
    try:
        assert vec.processes == workers
    finally:
        vec.close()
