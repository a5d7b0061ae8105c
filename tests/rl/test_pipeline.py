"""Pipelined rollouts: the buffer lockstep collects, a group of games at a time."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback

from sc2data.rl.batched import BatchedNarration
from sc2data.rl.narration import Narration
from sc2data.rl.pipeline import PipelinedPPO
from sc2data.rl.train import RLConfig, check_config, make_vec_env, new_model
from sc2data.rl.vector import BuildMarinesVecEnv, GameConfig, spans
from sc2data.schema import Schema, StackBatch

CFG = dict(out="unused", action_space="paper", reward="narration", threshold=2.0, envs=5,
           rollout=40, batch_size=40, episode_steps=15, seed=2, threads=1)


def _rollout(mem: Path, groups: int, processes: int, replay: np.ndarray | None = None,
             callback: BaseCallback | None = None) -> tuple[PipelinedPPO, Any, bool]:
    """A model's first rollout with ``groups`` groups and the narration reward; with ``replay``
    (a buffer's actions, ``(steps, games, 3)``) its policy takes those decisions, whatever rows
    it is asked for."""
    cfg = RLConfig(processes=processes, env_groups=groups, mem=str(mem),  # type: ignore[arg-type]
                   **CFG)
    narration, scorer = check_config(cfg)
    vec = make_vec_env(cfg, scorer, narration)
    model = new_model(cfg, vec, cfg.seed)
    if replay is not None:
        policy, n, asked = model.policy, cfg.envs, [0]

        def forward(obs: Any, deterministic: bool = False, action_masks: Any = None) -> Any:
            b = len(obs["screen"])
            step, row = divmod(asked[0], n)
            asked[0] += b
            actions = torch.as_tensor(replay[step, row:row + b])
            values, log_probs, _ = policy.evaluate_actions(obs, actions, action_masks)
            return actions, values, log_probs

        policy.forward = forward  # type: ignore[method-assign]
    model._setup_learn(cfg.rollout * cfg.envs, callback=None)
    cb = callback or _Count()
    cb.init_callback(model)
    done = model.collect_rollouts(vec, cb, model.rollout_buffer, cfg.rollout)
    return model, vec, done


class _Count(BaseCallback):
    def __init__(self, stop_at: int | None = None) -> None:
        super().__init__()
        self.stop_at, self.steps = stop_at, 0

    def _on_step(self) -> bool:
        self.steps += 1
        assert self.locals["infos"] and len(self.locals["dones"]) == self.training_env.num_envs
        return self.steps != self.stop_at


def test_a_pipelined_rollout_is_lockstep_s_rollout(mem_run: Path) -> None:
    """Two groups of games (stepped in two worker processes or in this one), taking lockstep's
    sampled decisions, fill the rollout buffer as lockstep did: the same observations, rewards,
    episode starts and masks (episodes end on the way, the narration pays), values and
    log-probabilities equal to float rounding."""
    lock, lock_vec, _ = _rollout(mem_run, 1, 0)
    replay = lock.rollout_buffer.actions.astype(np.int64)
    assert len({tuple(a) for a in replay.reshape(-1, 3)}) > 50  # sampled, varied decisions
    threads = torch.get_num_threads()
    try:
        for processes in (2, 0):
            piped, vec, done = _rollout(mem_run, 2, processes, replay)
            try:
                assert done and piped.num_timesteps == lock.num_timesteps == 40 * 5
                a, b = lock.rollout_buffer, piped.rollout_buffer
                for k in a.observations:
                    assert (a.observations[k] == b.observations[k]).all(), k
                for name in ("actions", "rewards", "episode_starts", "action_masks"):
                    assert (getattr(a, name) == getattr(b, name)).all(), name
                assert a.episode_starts[1:].sum() >= 10  # every game ended twice
                assert (a.rewards > 0).sum() > 10  # and the narration paid on the way
                for name in ("values", "log_probs", "advantages", "returns"):
                    np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-4,
                                               atol=1e-5, err_msg=name)
                assert all((lock._last_obs[k] == piped._last_obs[k]).all()  # type: ignore[index]
                           for k in a.observations)
                assert torch.get_num_threads() == threads  # the update gets its threads back
            finally:
                vec.close()
    finally:
        lock_vec.close()


def test_a_rollout_stopped_by_its_callback_leaves_no_game_stepping(mem_run: Path) -> None:
    model, vec, done = _rollout(mem_run, 2, 2, callback=_Count(stop_at=3))
    try:
        assert not done and model.num_timesteps == 3 * 5
        assert vec._inflight == []
        obs, *_ = vec.step(np.zeros((5, 3), dtype=np.int64))  # the vector steps on as before
        assert len(obs["screen"]) == 5
    finally:
        vec.close()


def test_parts_are_waited_for_in_the_order_sent() -> None:
    vec = BuildMarinesVecEnv(GameConfig("macro", game_loops=8 * 20), 3, processes=2)
    try:
        vec.reset()
        for lo, hi in spans(3, 2):
            vec.step_async_rows(lo, hi, np.zeros(hi - lo, dtype=np.int64))
        with pytest.raises(RuntimeError, match="order"):
            vec.step_wait_rows(2, 3)
        with pytest.raises(RuntimeError, match="stepping"):
            vec.reset()
        for lo, hi in spans(3, 2):
            obs, rewards, dones, infos = vec.step_wait_rows(lo, hi)
            assert len(rewards) == len(dones) == len(infos) == hi - lo
            assert all(len(v) == hi - lo for v in obs.values())
            assert vec.action_masks(lo, hi).shape[0] == hi - lo
    finally:
        vec.close()


def test_groups_beyond_the_games_are_as_many_as_the_games(mem_run: Path) -> None:
    assert spans(5, 2) == [(0, 2), (2, 5)] or spans(5, 2) == [(0, 3), (3, 5)]
    assert spans(1, 1) == [(0, 1)] and spans(3, 0) == []
    model, vec, done = _rollout(mem_run, 9, 0)
    try:
        assert done and model.num_timesteps == 40 * 5
    finally:
        vec.close()


class _MineralScorer:
    """A MEM stand-in: a stack matches command ``c`` where its second frame's minerals are ``c``
    modulo the number of commands."""

    schema = Schema.from_names([], [])  # no layer: the non-spatial vectors

    def embed_texts(self, commands: list[str]) -> None:
        pass

    def distances(self, batch: StackBatch, commands: list[str]) -> np.ndarray:
        minerals = batch.vector("player", "minerals")[:, 1].astype(int)
        return np.where(minerals[:, None] % len(commands) == np.arange(len(commands)), 0.0, 1.0)


@pytest.mark.parametrize("shaping", ["event", "potential"])
def test_the_narration_state_of_a_part_is_its_own_games(shaping: str) -> None:
    """The batched narration scored a part of the games at a time (``first``) pays what it pays
    scored for all games at once, each game keeping its own place in the narration."""
    n, parts = 5, spans(5, 2)
    narration = Narration(("one", "two", "three"), "test")
    whole, split = (BatchedNarration(_MineralScorer(), narration, bonus=0.5, patience=3,  # type: ignore[arg-type]
                                     shaping=shaping) for _ in range(2))
    whole.reset(n)
    split.reset(n)
    rng = np.random.default_rng(0)
    player = next(v for v in whole.schema.vectors if v.name == "player")
    minerals = list(player.fields).index("minerals")
    for t in range(60):
        steps = rng.integers(1, 4, size=n)  # pysc2 steps per decision: 1-3 stacks
        frames = {v.name: np.zeros((n, 4, v.size), v.dtype) for v in whole.schema.vectors}
        frames["player"][..., minerals] = rng.integers(0, 3, size=(n, 4))
        done = rng.random(n) < 0.1
        a, _ = whole(frames, steps + 1, done)
        b = np.concatenate([split({k: v[lo:hi] for k, v in frames.items()}, steps[lo:hi] + 1,
                                  done[lo:hi], first=lo)[0] for lo, hi in parts])
        assert (a == b).all(), t
        assert (whole.index == split.index).all() and (whole.matched == split.matched).all()
    assert len(set(whole.index)) > 1  # the games were at different commands


def test_the_groups_come_from_the_run_s_settings_not_the_model_file(tmp_path: Path) -> None:
    cfg = RLConfig(out="unused", action_space="macro", envs=2, env_groups=2, processes=0)
    vec = make_vec_env(cfg)
    try:
        model = new_model(cfg, vec, 0)
        assert model.groups == 2
        model.save(tmp_path / "model.zip")
    finally:
        vec.close()
    assert PipelinedPPO.load(tmp_path / "model.zip", device="cpu").groups == 1


@pytest.mark.parametrize("space", ["paper", "macro"])
def test_parts_scored_together_pay_what_each_part_scored_alone_pays(space: str) -> None:
    """Parts waited for unscored, each sent to step again before the parts are scored in one
    call (as a pipelined rollout does, their frames overwritten meanwhile), get the rewards,
    ends and infos of parts scored as they are waited for (in the macro space, parts whose
    decisions filled different numbers of frames); mixing the two ways, or resetting with a
    part unscored, is an error."""
    narration = Narration(("one", "two", "three"), "test")
    n, parts = 5, spans(5, 2)
    alone, together = (BuildMarinesVecEnv(
        GameConfig(space, game_loops=8 * (12 if space == "paper" else 60)), n, processes=p,
        shaping=BatchedNarration(_MineralScorer(), narration, bonus=0.5, patience=3))  # type: ignore[arg-type]
        for p in (0, 2))
    rng = np.random.default_rng(1)

    def send(lo: int, hi: int) -> None:
        masks = alone.action_masks(lo, hi)
        assert (masks == together.action_masks(lo, hi)).all()
        if space == "macro":
            a = np.array([rng.choice(np.flatnonzero(m)) for m in masks])
        else:  # a function the mask allows, at a random point
            f = [rng.choice(np.flatnonzero(m[:10])) for m in masks]
            a = np.column_stack([f, rng.integers(0, 64, size=(hi - lo, 2))])
        alone.step_async_rows(lo, hi, a)
        together.step_async_rows(lo, hi, a)

    try:
        for v in (alone, together):
            v.seed(4)
            v.reset()
        for lo, hi in parts:
            send(lo, hi)
        paid = ends = uneven = 0
        for t in range(30):
            got, waits = [], []
            for lo, hi in parts:
                got.append(alone.step_wait_rows(lo, hi))
                waits.append(together.step_wait_rows_unscored(lo, hi))
                send(lo, hi)  # the part steps on before it is scored
            if t == 0:
                with pytest.raises(RuntimeError, match="score_waited"):
                    together.step_wait_rows(*parts[0])
            rewards, dones, infos = together.score_waited()
            assert (rewards == np.concatenate([g[1] for g in got])).all(), t
            assert (dones == np.concatenate([g[2] for g in got])).all()
            for (obs, done), g in zip(waits, got):
                assert (done == g[2]).all() and all((obs[k] == g[0][k]).all() for k in obs)
            flat = [i for g in got for i in g[3]]
            for a, b in zip(infos, flat, strict=True):
                assert a.keys() == b.keys()
                assert all(a[k] == b[k] for k in a if k != "terminal_observation")
                if "terminal_observation" in a:
                    assert all((a["terminal_observation"][k] == b["terminal_observation"][k])
                               .all() for k in a["terminal_observation"])
            paid += int((rewards > 0).sum())
            ends += int(dones.sum())
            longest = {max(i["env_steps"] for i in g[3]) for g in got}
            uneven += len(longest) > 1  # one part's decisions filled more frames
        assert paid > 5 and ends >= n  # the narration paid and every game ended on the way
        assert uneven or space == "paper"
        assert together.score_waited()[0].shape == (0,)
        for lo, hi in parts:
            alone.step_wait_rows(lo, hi)
            together.step_wait_rows_unscored(lo, hi)
        with pytest.raises(RuntimeError, match="scored"):
            together.reset()
        assert len(together.score_waited()[0]) == n
    finally:
        alone.close()
        together.close()
