"""Can a run's policy network, on the run's observation, play the macro-rules agent's game?
Behaviour cloning of that agent in the macro space, as a diagnostic of the RL experiment.

The macro-space learners end as a fixed ranking of the six macros that only the action mask
moves (BENCHMARKS.md, "Far sites, 10 seeds"), so argmax play repeats one macro. Either the
network cannot tell the states apart that the rules tell apart (what it sees, or how), or PPO's
signal does not teach it to. This script separates the two: it plays ``--episodes`` of the
macro-rules agent on the run's env (:func:`ppo_gradients.demonstrate`: the agent asked at each
decision which macro it would start, the env playing it; seeds 500,000,000 on, which training
and evaluation never use), fits a fresh policy of the run's settings to the agent's choices by
maximum likelihood under the action masks (Adam, minibatches of 256; the value head untouched),
and reports, per macro the agent chose, how often the policy's most likely macro is the same on
``--held-out`` episodes it did not see (and their mean, the balanced accuracy: the agent waits
at most decisions). It then writes the cloned policy as a run folder (the run's
``config.json``, the policy committed as ``rl train`` commits one, no training episodes) so that
``sc2data rl evaluate OUT`` plays it on the evaluation episodes, sampled and argmax, like any
run, and
``benchmarks/policy_trace.py OUT`` traces it, and ``sc2data rl train --init-policy OUT`` starts
PPO from it; ``OUT/clone.json`` records what was fitted.

``--dagger R`` then runs R rounds of DAgger (Ross et al. 2011): the clone plays
``--dagger-episodes`` episodes of its own (seeds apart from the rules'; argmax on even episodes,
sampled on odd), the rules label every state it reaches with the macro they would choose there
(their timers set from the clone's own choices), those decisions join the training set and the
fit goes on ``--dagger-epochs`` epochs at ``--dagger-lr``. A clone fitted to the rules' states
alone meets states the rules never reach once its first choice differs; DAgger trains it on
them. Each round's marines (the clone's own episodes, argmax and sampled) are printed and
recorded; a last round of episodes measures the last fit, and the policy kept is the one whose
round made the most marines by argmax (DAgger's choice of the best policy of the sequence, on
training-side seeds: the evaluation episodes stay unseen).

    python benchmarks/clone_rules.py RUN --out OUT [--episodes 16] [--held-out 2] [--epochs 30]
        [--history] [--balanced] [--dagger 0] [--dagger-episodes 8] [--dagger-epochs 10]
        [--dagger-lr 3e-4]

``--history`` gives the policy the time since each macro last acted (``rl train --history``),
which the rules' own timers use and the screen does not show.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from ppo_gradients import DEMO_SEED, Demonstrations, demonstrate, joined

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import PARTIAL, publish, write_atomic
from sc2data.rl import runs
from sc2data.rl.obs import MACROS
from sc2data.rl.train import load_config, make_vec_env, new_model


def split(demos: Demonstrations, held_out: int) -> tuple[np.ndarray, np.ndarray]:
    """Decision indices of the first episodes and of the last ``held_out``."""
    test = demos.episodes >= len(demos.marines) - held_out
    return np.flatnonzero(~test), np.flatnonzero(test)


def batch(demos: Demonstrations, idx: np.ndarray) -> dict[str, torch.Tensor]:
    return {k: torch.as_tensor(v[idx]).float() for k, v in demos.obs.items()}


def predictions(policy: Any, demos: Demonstrations, idx: np.ndarray) -> np.ndarray:
    """The policy's most likely allowed action at each of the decisions ``idx``: a macro (in
    the paper space, ``(function, x, y)``)."""
    out = []
    with torch.no_grad():
        for part in np.array_split(idx, max(1, len(idx) // 512)):
            dist = policy.get_distribution(batch(demos, part), action_masks=demos.masks[part])
            out.append(dist.get_actions(deterministic=True).numpy())
    return np.concatenate(out) if out else np.zeros((0, *demos.actions.shape[1:]), np.int64)


def recalls(policy: Any, demos: Demonstrations, idx: np.ndarray) -> dict[str, float]:
    """Per macro the agent chose at ``idx``, the share of those decisions where the policy's
    most likely macro is the same; ``balanced``: their mean (the agent waits at most decisions,
    so a policy that always waits is right at most of them and 1/6 balanced)."""
    best, truth = predictions(policy, demos, idx), demos.actions[idx]
    out = {m: float(np.mean(best[truth == i] == i)) for i, m in enumerate(MACROS)
           if (truth == i).any()}
    out["balanced"] = float(np.mean(list(out.values()))) if out else float("nan")
    return out


def policy_optimizer(policy: Any, lr: float) -> torch.optim.Optimizer:
    """Adam over the policy's parameters but the value head's (cloning leaves it untouched)."""
    return torch.optim.Adam([p for n, p in policy.named_parameters() if "value_net" not in n],
                            lr=lr)


def class_weights(labels: np.ndarray, train: np.ndarray, n: int, balanced: bool) -> np.ndarray:
    """Each of the ``n`` classes' weight in the loss: 1, or with ``balanced`` the inverse of its
    share of the training decisions (0 for one never taken)."""
    if not balanced:
        return np.ones(n)
    counts = np.bincount(labels[train], minlength=n).astype(float)
    return np.where(counts > 0, len(train) / (n * np.maximum(counts, 1)), 0.0)


def likelihood_epoch(policy: Any, opt: torch.optim.Optimizer, demos: Demonstrations,
                     train: np.ndarray, weight: np.ndarray, labels: np.ndarray,
                     rng: np.random.Generator) -> float:
    """One epoch of maximum likelihood of the demonstrated actions under their masks,
    minibatches of 256, each decision weighted by its class's ``weight`` (``labels``: its
    class); the mean loss."""
    losses = []
    for part in np.array_split(rng.permutation(train), max(1, len(train) // 256)):
        _, log_prob, _ = policy.evaluate_actions(
            batch(demos, part), torch.as_tensor(demos.actions[part]),
            action_masks=demos.masks[part])
        w = torch.as_tensor(weight[labels[part]], dtype=log_prob.dtype)
        loss = -(w * log_prob).sum() / w.sum()
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    return float(np.mean(losses))


def fit(policy: Any, demos: Demonstrations, train: np.ndarray, test: np.ndarray, epochs: int,
        lr: float, seed: int, balanced: bool = False) -> list[dict[str, float]]:
    """Maximum likelihood of the agent's macros under the masks; per epoch the mean negative
    log-likelihood and the balanced accuracy (:func:`recalls`) on both parts. ``balanced``:
    each decision weighted by the inverse of its macro's share of the training decisions, so
    that every macro weighs as much in the loss as the waits do."""
    opt = policy_optimizer(policy, lr)
    rng = np.random.default_rng(seed)
    weight = class_weights(demos.actions, train, len(MACROS), balanced)
    log = []
    for epoch in range(epochs):
        nll = likelihood_epoch(policy, opt, demos, train, weight, demos.actions, rng)
        row = {"epoch": epoch + 1, "nll": nll,
               "train_balanced": recalls(policy, demos, train)["balanced"],
               "held_out_balanced": recalls(policy, demos, test)["balanced"]}
        log.append(row)
        print(f"epoch {row['epoch']:3d}  nll {row['nll']:.3f}  balanced accuracy train "
              f"{row['train_balanced']:.3f}  held out {row['held_out_balanced']:.3f}", flush=True)
    return log


DAGGER_SEED = DEMO_SEED + 100_000
"""Round r's episode e is seeded ``DAGGER_SEED + 1,000·r + e``: apart from the rules' episodes
(``DEMO_SEED`` on), training's and evaluation's."""


def dagger_episodes(model: Any, cfg: Any, r: int, episodes: int
                    ) -> tuple[Demonstrations, dict[str, list[int]], float]:
    """Round ``r``'s episodes of the clone (argmax on even ones, sampled on odd), every state
    labelled by the rules; the marines of each mode and how often the clone's most likely macro
    was the rules' choice."""
    played: dict[str, list[int]] = {"argmax": [], "sampled": []}
    new = None
    for e in range(episodes):
        mode = "argmax" if e % 2 == 0 else "sampled"
        d = demonstrate(cfg, 1, model, label=True, deterministic=mode == "argmax",
                        first_seed=DAGGER_SEED + 1000 * r + e)
        played[mode] += d.marines
        new = d if new is None else joined(new, d)
    assert new is not None
    agree = float(np.mean(predictions(model.policy, new, np.arange(len(new.actions)))
                          == new.actions))
    return new, played, agree


def dagger(model: Any, cfg: Any, demos: Demonstrations, train: np.ndarray, test: np.ndarray,
           args: argparse.Namespace, episodes: Callable[..., Any] = dagger_episodes,
           fit_more: Callable[..., Any] = fit
           ) -> tuple[Demonstrations, list[dict[str, Any]], list[Any]]:
    """``args.dagger`` rounds (see the module docstring), then one more round of episodes that
    only measures the last fit; the model is left with the policy whose round made the most
    marines by argmax (round r measures the policy fitted before it). Returns the aggregate,
    the rounds' records and the fits' log. ``episodes`` plays and labels a round (as
    :func:`dagger_episodes`) and ``fit_more`` fits (as :func:`fit`): ``clone_scripted.py``
    passes its own for the paper space."""
    rounds: list[dict[str, Any]] = []
    policies, log = [], []
    for r in range(1, args.dagger + 2):
        t0 = time.perf_counter()
        new, played, agree = episodes(model, cfg, r, args.dagger_episodes)
        policies.append(copy.deepcopy(model.policy.state_dict()))
        rounds.append({"round": r, "argmax_marines": played["argmax"],
                       "sampled_marines": played["sampled"], "decisions": int(len(new.actions)),
                       "agreement": agree})
        print(f"DAgger round {r}: the clone made {np.mean(played['argmax']):.1f} marines by "
              f"argmax, {np.mean(played['sampled']):.1f} sampled; {len(new.actions)} decisions, "
              f"its argmax the labeller's choice at {agree:.3f} of them "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
        if r > args.dagger:
            break
        start = len(demos.actions)
        demos = joined(demos, new)
        train = np.concatenate([train, np.arange(start, len(demos.actions))])
        log += fit_more(model.policy, demos, train, test, args.dagger_epochs, args.dagger_lr,
                        cfg.seed + r, args.balanced)
    best = max(range(len(rounds)), key=lambda i: (np.mean(rounds[i]["argmax_marines"]), i))
    model.policy.load_state_dict(policies[best])
    for i, row in enumerate(rounds):
        row["kept"] = i == best
    print(f"kept the policy round {best + 1} played", flush=True)
    return demos, rounds, log


def clone(cfg: Any, demos: Demonstrations, train: np.ndarray, test: np.ndarray,
          args: argparse.Namespace, measure: Callable[..., Any] = recalls,
          fit_first: Callable[..., Any] = fit, episodes: Callable[..., Any] = dagger_episodes
          ) -> tuple[Any, Demonstrations, Any, Any, list[Any], list[dict[str, Any]]]:
    """A fresh model of the run's settings, its policy fitted to ``demos`` (``fit_first``) and
    then, with ``args.dagger``, through DAgger's rounds (``episodes``); ``measure`` (held out)
    before and after. Returns the model, the demonstrations (with DAgger's), both
    measurements, the fits' log and DAgger's rounds."""
    vec = make_vec_env(cfg)
    try:
        model = new_model(cfg, vec, cfg.seed)
        if args.init is not None:
            start_from_clone(model, args.init, vec)
        before = measure(model.policy, demos, test)
        print(f"the untrained policy, held out: {before}", flush=True)
        log = fit_first(model.policy, demos, train, test, args.epochs, args.lr, cfg.seed,
                        args.balanced)
        after = measure(model.policy, demos, test)
        print(f"the cloned policy, held out: {after}", flush=True)
        rounds: list[dict[str, Any]] = []
        if args.dagger:
            demos, rounds, more = dagger(model, cfg, demos, train, test, args, episodes,
                                         fit_first)
            log += more
            after = measure(model.policy, demos, test)
            print(f"after DAgger, held out: {after}", flush=True)
    finally:
        vec.close()
    return model, demos, before, after, log, rounds


def start_from_clone(model: Any, src: Path, vec: Any) -> None:
    """Give ``model`` the policy of the trained run ``src``. A spatial policy with the ``cell``
    point head fits one with the ``pixel`` head: what it lacks (the within-cell convolution and
    the pixels' preferences) starts at zero, so the model starts as exactly ``src``'s policy."""
    state = runs.load_model(src, vec, "cpu").policy.state_dict()
    missing, unexpected = model.policy.load_state_dict(state, strict=False)
    if unexpected or any(not k.startswith(("within.", "place")) for k in missing):
        raise SystemExit(f"--init {src}: its network does not fit the run's "
                         f"(missing {missing}, unexpected {unexpected})")
    if missing:
        with torch.no_grad():
            for k in missing:
                model.policy.get_parameter(k).zero_()


def add_options(ap: argparse.ArgumentParser, *, epochs: int, lr: float, dagger_episodes: int,
                dagger_epochs: int, unit: str) -> None:
    """The options both cloning scripts take (``unit``: what ``--balanced`` weighs)."""
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--episodes", type=int, default=16)
    ap.add_argument("--held-out", type=int, default=2)
    ap.add_argument("--epochs", type=int, default=epochs)
    ap.add_argument("--lr", type=float, default=lr)
    ap.add_argument("--balanced", action="store_true",
                    help=f"weight each {unit} by the inverse of its share of the decisions")
    ap.add_argument("--dagger", type=int, default=0, help="DAgger rounds after the first fit")
    ap.add_argument("--dagger-episodes", type=int, default=dagger_episodes,
                    help="the clone's episodes a round")
    ap.add_argument("--dagger-epochs", type=int, default=dagger_epochs,
                    help="epochs of fitting a round")
    ap.add_argument("--dagger-lr", type=float, default=3e-4, help="Adam's step in the rounds")
    ap.add_argument("--init", type=Path, default=None,
                    help="start the fit from this run's policy (e.g. an earlier clone)")


def checked_config(args: argparse.Namespace, prog: str, space: str, why: str) -> Any:
    """The settings run's config, the options checked: one line and an exit where one is wrong
    (``why``: what needs the ``space``)."""
    if args.episodes <= args.held_out or args.held_out < 1 or args.epochs < 1:
        raise SystemExit(f"{prog}: --held-out must be at least 1 and below --episodes, "
                         "--epochs at least 1")
    if args.dagger < 0 or args.dagger_episodes < 1 or args.dagger_epochs < 1 or \
            args.dagger_lr <= 0:
        raise SystemExit(f"{prog}: --dagger must be at least 0, --dagger-episodes and "
                         "--dagger-epochs at least 1, --dagger-lr above 0")
    if args.out.exists():
        raise SystemExit(f"{prog}: {args.out} exists; pick another --out")
    try:
        cfg = load_config(args.run)
    except Sc2DataError as e:
        raise SystemExit(f"{prog}: {e}") from None
    if cfg.action_space != space:
        raise SystemExit(f"{prog}: {why}; {args.run} is a {cfg.action_space}-space run")
    return cfg


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a macro-space run whose settings the clone takes")
    add_options(ap, epochs=30, lr=3e-4, dagger_episodes=8, dagger_epochs=10, unit="macro")
    ap.add_argument("--history", action=argparse.BooleanOptionalAction, default=None,
                    help="the time since each macro last acted (default: as the run)")
    args = ap.parse_args()
    cfg = checked_config(args, "clone_rules.py", "macro",
                         "the macro-rules agent plays the macro space")
    history = cfg.history if args.history is None else args.history
    cfg = dataclasses.replace(cfg, envs=1, processes=0, reward="sparse", shaping="event",
                              mem=None, narration=None, history=history)
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    demos = demonstrate(cfg, args.episodes)
    train, test = split(demos, args.held_out)
    shares = {m: round(float(np.mean(demos.actions == i)), 4) for i, m in enumerate(MACROS)}
    print(f"macro-rules: {len(demos.actions)} decisions over {args.episodes} episodes, "
          f"{np.mean(demos.marines):.1f} marines an episode ({time.perf_counter() - t0:.0f} s); "
          f"decisions {shares}", flush=True)
    model, demos, before, after, log, rounds = clone(cfg, demos, train, test, args)
    record = {"like": str(args.run), "episodes": args.episodes, "held_out": args.held_out,
              "decisions": int(len(demos.actions)), "rules_marines": demos.marines,
              "rules_decisions": shares, "epochs": args.epochs, "lr": args.lr,
              "balanced": args.balanced,
              "history": history, "untrained_held_out": before, "cloned_held_out": after,
              "log": log, "dagger": {"rounds": rounds, "episodes": args.dagger_episodes,
                                     "epochs": args.dagger_epochs, "lr": args.dagger_lr}}
    write_clone(args.out, cfg, model, record)
    print(f"wrote {args.out} ({time.perf_counter() - t0:.0f} s); next: sc2data rl evaluate "
          f"{args.out}")


def write_clone(out: Path, cfg: Any, model: Any, record: dict[str, Any]) -> None:
    """The cloned policy as a run folder ``out`` (``cfg``'s ``config.json``, the policy
    committed as ``rl train`` commits one, no training episodes) with ``record`` as its
    ``clone.json``; written beside ``out`` and published whole (as ``rl fork`` does): an
    interrupted clone leaves no ``out`` that looks like a run."""
    tmp = out.with_name(f".{out.name}{PARTIAL}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        runs.write_record(tmp / runs.CONFIG, cfg.identity())
        runs.commit(tmp, model, [], {"config": cfg.identity(), "episodes": []},
                    {"timesteps": 0, "env_steps": 0, "episodes": 0, "resumes": 0})
        write_atomic(tmp / "clone.json", (json.dumps(record, indent=1) + "\n").encode())
        publish(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


if __name__ == "__main__":
    main()
