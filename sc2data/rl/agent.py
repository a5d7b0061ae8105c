"""A trained ``sc2data rl train`` policy as a pysc2 agent: ``--agent policy:RUN`` in rollouts.

The agent plays the run's MaskablePPO policy (``RUN/model.zip``) on raw pysc2 timesteps, so any
rollout, recipe, ``build`` or live ``render`` can play it, on the simulator or the real game:

* it sees what the policy was trained on: the run's observation (:class:`~sc2data.rl.obs.Observer`
  of :meth:`~sc2data.rl.train.RLConfig.obs_config`, with a :class:`~sc2data.rl.obs.MacroClock`
  kept as the env keeps it) and the same action masks;
* it acts in the run's action space: a paper action becomes one call
  (:func:`~sc2data.rl.envs.paper_call`); a macro is played out over the following steps by the
  reduced-random agent's macro code exactly as :class:`~sc2data.rl.envs.BuildMarinesGym` plays
  it (a call that turns out unavailable ends the macro; a macro that sends nothing plays one
  ``no_op``; the next decision is taken on the observation after the macro's last call);
* actions are **sampled** (a data set wants the policy's spread, not its mode), from a torch
  generator of the agent's own, seeded with the episode's agent seed, as is the macro code's
  generator: one seed, one episode, whatever else runs in the process.

The game room cannot import this room, so the kind is registered with
:func:`sc2data.game.agents.register_agent_kind` when ``sc2data.rl`` is imported; the factory
(:class:`PolicyFactory`) is picklable and lives here, so a spawned rollout worker that unpickles
it imports this module itself. The factory checks the checkpoint's sha256 when it loads it: the
dataset records that sha256 (``agent_sha256``), and a run trained on meanwhile is refused.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from sc2data._pysc2 import actions, base_agent
from sc2data.game.agents import AgentSpec, ReducedRandomAgent, register_agent_kind
from sc2data.game.screen import ScreenView
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import sha256_file
from sc2data.ground.vocab import SCREEN_SIZE
from sc2data.rl.runs import MODEL

CHECKPOINT = MODEL
_LOADED: dict[tuple[str, str], tuple[Any, Any]] = {}
"""(run, sha256) → (model, RLConfig), one load per process (a factory makes an agent per
episode)."""

def _load(run: str, sha256: str) -> tuple[Any, Any]:
    """The run's policy and settings, once per process; the checkpoint must be ``sha256``."""
    key = (run, sha256)
    if key not in _LOADED:
        from sc2data.rl.train import load_config, require_rl

        require_rl("a policy:RUN agent")
        path = Path(run)
        cfg = load_config(path)
        if sha256_file(path / CHECKPOINT) != sha256:
            raise Sc2DataError(f"{path / CHECKPOINT} changed since this rollout began (trained "
                               f"on?); roll the new checkpoint out into another --out")
        from sb3_contrib import MaskablePPO

        _LOADED[key] = (MaskablePPO.load(path / CHECKPOINT, device="cpu"), cfg)
    return _LOADED[key]


class PolicyAgent(base_agent.BaseAgent):
    """A trained policy playing pysc2 timesteps, sampled (see the module docstring)."""

    def __init__(self, model: Any, cfg: Any, seed: int) -> None:
        super().__init__()
        from sc2data.rl.obs import MacroClock, Observer, history_actions

        self.model = model
        self.cfg = cfg
        self.seed = seed
        self.observer = Observer(cfg.obs_config())
        self._macro: Iterator[actions.FunctionCall] | None = None
        self._sent = 0
        self.clock = MacroClock(history_actions(cfg.action_space))
        """When each macro (or paper function) last acted, as the env's (the observation's
        ``history``)."""
        self.reset()

    def reset(self) -> None:
        """Start an episode: the generators restart from the seed, so a reset replays it."""
        import torch

        super().reset()
        seeds = np.random.SeedSequence(self.seed).generate_state(2, np.uint32)
        self._torch = torch.Generator().manual_seed(int(seeds[0])).get_state()
        self.expander = ReducedRandomAgent(int(seeds[1]), sites=self.cfg.macro_sites)
        self._macro = None
        self._sent = 0
        self.clock.reset()

    def step(self, obs: Any) -> actions.FunctionCall:
        super().step(obs)
        from sc2data.rl.envs import MACROS, macro_feasible, paper_call
        from sc2data.rl.obs import game_loop

        view = ScreenView(obs)
        if self.cfg.action_space == "paper":
            f, x, y = (int(a) for a in self._decide(obs, self._paper_mask(view)).reshape(3))
            self.clock.acted(f, game_loop(obs.observation))
            return paper_call(f, x, y)
        self.expander.view = view
        for _ in range(2):  # the running macro's next call, or a new decision on this view
            if self._macro is None:
                mask = macro_feasible(view)
                if self.cfg.merge_waits and mask.sum() == 1:  # forced: the env asks no policy
                    return actions.FUNCTIONS.no_op()
                name = MACROS[int(self._decide(obs, mask))]
                macro = self.expander.macro(name)
                cost = self.expander.COST.get(name, 0)
                self._macro = (self.expander.save_up(cost, macro, self.expander.PATIENCE)
                               if cost else macro)
                self.clock.start(name)
                self._sent = 0
            call = next(self._macro, None)
            if call is None or not view.can(call):
                self._macro = None
                if self._sent == 0:  # the macro sent nothing: one no_op, as the env plays it
                    return actions.FUNCTIONS.no_op()
                continue  # it ended after its last call: decide again on this observation
            self._sent += 1
            self.clock.sent(call, game_loop(obs.observation))
            return call
        return actions.FUNCTIONS.no_op()

    def _decide(self, obs: Any, mask: np.ndarray) -> np.ndarray:
        """One sampled action of the policy, drawn from this agent's own torch generator, on one
        torch thread (a batch of one gains nothing from more: two made a paper-space step 6×
        slower on this project's busy 2-core machine, 95 ms against 15); the caller's thread
        count and generator are left as they were."""
        import torch

        arrays = self.observer(obs.observation, clock=self.clock)
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            with torch.random.fork_rng(devices=[]):
                torch.set_rng_state(self._torch)
                action, _ = self.model.predict(arrays, deterministic=False, action_masks=mask)
                self._torch = torch.get_rng_state()
        finally:
            torch.set_num_threads(threads)
        return np.asarray(action)

    @staticmethod
    def _paper_mask(view: ScreenView) -> np.ndarray:
        """The paper space's mask, as the env's ``action_masks``: available functions, then
        every x and every y."""
        from sc2data.rl.envs import PAPER_FUNCTIONS

        available = view.available
        funcs = [int(actions.FUNCTIONS[n].id) in available for n in PAPER_FUNCTIONS]
        return np.concatenate([np.array(funcs, bool), np.ones(2 * SCREEN_SIZE, bool)])


class PolicyFactory:
    """``seed -> PolicyAgent`` for one run's checkpoint of a known sha256; picklable."""

    def __init__(self, run: str, sha256: str) -> None:
        self.run = run
        self.sha256 = sha256

    def __call__(self, seed: int) -> PolicyAgent:
        model, cfg = _load(self.run, self.sha256)
        return PolicyAgent(model, cfg, seed)


def resolve(run: str) -> AgentSpec:
    """The agent of ``policy:RUN``: a one-line error unless RUN is a trained run."""
    from sc2data.rl.train import load_config

    cfg = load_config(Path(run))
    sha = sha256_file(Path(run) / CHECKPOINT)
    return AgentSpec(PolicyFactory(run, sha), sha256=sha,
                     about={"action_space": cfg.action_space, "reward": cfg.reward,
                            "obs": cfg.obs, "seed": cfg.seed})


register_agent_kind("policy", resolve, arg="RUN")
