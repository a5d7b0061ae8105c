"""Narration-guided reinforcement learning on BuildMarines.

Gymnasium environments (:mod:`sc2data.rl.envs`), reward wrappers — the game's sparse reward,
shaping by the labelling rules, shaping by a narration and a trained MEM
(:mod:`sc2data.rl.rewards`) — and MaskablePPO training and evaluation (:mod:`sc2data.rl.train`,
``sc2data rl …``). Needs the optional ``rl`` extra: ``pip install 'sc2data[rl]'``.

Importing this package registers ``sc2data/BuildMarines-macro-v0`` and
``sc2data/BuildMarines-paper-v0`` with gymnasium (where gymnasium is installed), so
``gymnasium.make("sc2data/BuildMarines-macro-v0")`` works after ``import sc2data.rl``; gymnasium
also imports it itself for ``gymnasium.make("sc2data.rl:sc2data/BuildMarines-macro-v0")``. It
also registers the ``policy:RUN`` rollout agent (:mod:`sc2data.rl.agent`) with the game room.
"""

from __future__ import annotations

ENV_IDS: dict[str, str] = {
    "macro": "sc2data/BuildMarines-macro-v0",
    "paper": "sc2data/BuildMarines-paper-v0",
}
"""Gymnasium ids by action space."""


def register() -> None:
    """Register the environments with gymnasium (idempotent; a no-op without gymnasium)."""
    try:
        import gymnasium
    except ImportError:
        return
    for space, env_id in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(env_id, entry_point="sc2data.rl.envs:BuildMarinesGym",
                               kwargs={"action_space": space})


register()

from sc2data.rl import agent as _agent  # noqa: E402,F401  registers the policy:RUN agent kind
