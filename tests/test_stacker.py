"""Stacker: live observations into the two-frame stacks a rollout stores."""

from __future__ import annotations

import numpy as np

import sc2data
from sc2data.schema import Schema


def test_stacks_pair_previous_and_current_as_the_rollout_does() -> None:
    env = sc2data.make_env("sim", seed=3)
    agent = sc2data.make_agent("scripted", seed=3)
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    agent.reset()
    schema = Schema.from_names(["unit_type"], ["camera"])
    stacker = sc2data.Stacker(schema)
    timestep = env.reset()[0]
    frames = [schema.extract(timestep.observation)]
    first = stacker.push(timestep)
    assert len(first) == 1 and set(first.arrays) == set(schema.keys())
    for k in schema.keys():  # the first step has no previous frame: (first, first)
        assert np.array_equal(first.arrays[k][0, 0], first.arrays[k][0, 1])
    stacks = []
    for _ in range(30):
        timestep = env.step([agent.step(timestep)])[0]
        frames.append({k: v.copy() for k, v in schema.extract(timestep.observation).items()})
        stacks.append(stacker.push(timestep))
    for t, s in enumerate(stacks):
        assert np.array_equal(s.vector("game_loop", "game_loop")[0], [8 * t, 8 * (t + 1)])
        for k in schema.keys():
            assert np.array_equal(s.arrays[k][0, 0], frames[t][k])
            assert np.array_equal(s.arrays[k][0, 1], frames[t + 1][k])
    again = stacker.push(env.reset()[0])  # a first TimeStep starts over
    assert (again.vector("game_loop", "game_loop") == 0).all()
    assert "StackBatch(size=1" in repr(again) and "(1, 2, 64, 64)" in repr(again)


def test_import_sc2data_is_cheap_and_names_are_lazy() -> None:
    import subprocess
    import sys

    code = ("import sys, sc2data; heavy = [m for m in ('pysc2', 'h5py', 'torch', 'pyarrow') "
            "if m in sys.modules]; assert not heavy, heavy; "
            "assert callable(sc2data.make_env) and callable(sc2data.make_agent); "
            "assert callable(sc2data.open_dataset) and callable(sc2data.load_model); "
            "assert sc2data.Stacker and sc2data.Schema and sc2data.StackBatch")
    subprocess.run([sys.executable, "-c", code], check=True)
