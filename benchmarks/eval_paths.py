"""Does a trained policy play the same in `rl evaluate`'s env as in the trainer's vector env?

A paper-space run can evaluate well below its last training episodes (BENCHMARKS.md, "The
sparse arm, seeds 2–7"). This script separates what could differ:

* ``--check-episode SEED``: one episode of the run's sampled play, stepped in
  ``BuildMarinesGym`` (what `rl evaluate` plays) and in the vector env (what training steps,
  ``--processes`` worker processes) with the same actions; prints the first step where an
  observation or a mask differs (``none``) and the marines of each;
* ``--seeds S…``: sampled play of the final policy on those games through `rl evaluate`'s own
  loop, reseeded before each episode as the evaluation is (``--no-reseed``: one random stream
  over all of them, as training draws); prints the marines of each episode and their mean.

The trainer's side (the same policy in the training env) is measured by resuming a copy of the
run with ``--learning-rate 1e-12`` for one episode of every game (``rl train --steps``).

    python benchmarks/eval_paths.py RUN --check-episode 1000004 --processes 2
    python benchmarks/eval_paths.py RUN --seeds 1000000 1000001 1000002 [--no-reseed]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np


def _env_and_model(run: Path) -> tuple[object, object, object]:
    import torch

    from sc2data.rl.envs import BuildMarinesGym
    from sc2data.rl.runs import load_model
    from sc2data.rl.train import game_loops, load_config

    torch.set_num_threads(1)
    cfg = load_config(run)
    env = BuildMarinesGym(cfg.action_space, backend=cfg.backend, obs=cfg.obs_config(),
                          game_loops=game_loops(cfg), merge_waits=cfg.merge_waits,
                          sites=cfg.macro_sites)
    return cfg, env, load_model(run, env)


def check_episode(run: Path, seed: int, processes: int) -> None:
    """Step one episode in both envs with the policy's actions; report the first difference."""
    import torch

    from sc2data.rl.train import check_config, make_vec_env

    cfg, env, model = _env_and_model(run)
    cfg = dataclasses.replace(cfg, envs=max(1, processes), processes=processes)  # type: ignore[type-var]
    vec = make_vec_env(cfg, *reversed(check_config(cfg)))
    try:
        obs, _ = env.reset(seed=seed)  # type: ignore[attr-defined]
        vec.seed(seed)
        vobs = vec.reset()
        first = None if all((vobs[k][0] == obs[k]).all() for k in obs) else "reset"
        torch.manual_seed(seed)
        info: dict = {}
        vinfo: dict = {}
        done = False
        t = 0
        while not done:
            mask = env.action_masks()  # type: ignore[attr-defined]
            if first is None and not (vec.action_masks()[0] == mask).all():
                first = f"mask at decision {t}"
            action, _ = model.predict(obs, action_masks=mask)  # type: ignore[attr-defined]
            obs, _, term, trunc, info = env.step(action)  # type: ignore[attr-defined]
            vobs, _, vdone, vinfos = vec.step(np.array([action] * vec.num_envs))
            vinfo = vinfos[0]
            done = bool(term or trunc)
            if first is None and (bool(vdone[0]) != done or not done and not all(
                    (vobs[k][0] == obs[k]).all() for k in obs)):
                first = f"observation at decision {t}"
            t += 1
    finally:
        vec.close()
    print(f"{t} decisions; first difference: {first or 'none'}; marines: evaluation env "
          f"{info.get('marines')}, vector env {vinfo.get('marines')}")


def play_seeds(run: Path, seeds: list[int], reseed: bool) -> None:
    """Sampled play through `rl evaluate`'s loop on ``seeds``."""
    import torch

    from sc2data.rl.evaluate import _episodes

    _, env, model = _env_and_model(run)
    if not reseed:
        torch.manual_seed(seeds[0])
        model.set_random_seed = lambda seed: None  # type: ignore[attr-defined]
    marines = _episodes(model, env, seeds, False, lambda: None)
    print(f"{'reseeded' if reseed else 'one stream'}: {marines}; mean {np.mean(marines):.2f} "
          f"± {np.std(marines, ddof=1) if len(marines) > 1 else 0:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--check-episode", type=int, help="Game seed of the episode to compare.")
    ap.add_argument("--processes", type=int, default=0, help="Worker processes of the vector "
                    "env (0: in this process).")
    ap.add_argument("--seeds", type=int, nargs="*", default=[])
    ap.add_argument("--no-reseed", action="store_true")
    a = ap.parse_args()
    if a.check_episode is not None:
        check_episode(a.run, a.check_episode, a.processes)
    if a.seeds:
        play_seeds(a.run, a.seeds, not a.no_reseed)


if __name__ == "__main__":
    main()
