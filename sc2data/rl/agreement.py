"""Is the MEM's reward right where the agent goes? MEM matches against the rules, on visited states.

The MEM was trained on states a random agent visits; a learning agent visits others. This plays
seeded episodes with a trained policy (``sc2data rl train``), forms every two-frame stack it
passes through (the stacks the reward wrappers score, see :mod:`sc2data.rl.rewards`), and asks
both judges of each command of the MEM's pair set:

* the **rule** (the labelling rule of the command's id, ``rules/``): does the stack show it?
* the **MEM**: is ``distance(stack, command text) < threshold``?

Per command, with the rule as ground truth: ``precision = TP / (TP + FP)`` (of the stacks the
MEM matched, the share the rule also fired on: how often a narration bonus is deserved) and
``recall = TP / (TP + FN)`` (of the stacks the rule fired on, the share the MEM matched: how
often a deserved bonus is paid). Stacks on which no rule fires are "null" stacks; the share of
them the MEM matches to no command is reported too.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sc2data.errors import Sc2DataError
from sc2data.files import write_atomic

AGREEMENT_SEED = 2_000_000
"""First episode seed of an agreement measurement (neither training's nor evaluation's)."""


def _ratio(a: int, b: int) -> float | None:
    return a / b if b else None


def agreement(run: Path, mem: Path, *, episodes: int = 3, deterministic: bool = False,
              threshold: float | None = None, out: Path | None = None) -> dict[str, Any]:
    """Play ``episodes`` episodes of the policy in ``run``; per-command agreement of the MEM in
    ``mem`` with the rules on the stacks visited. Written to ``out`` (default
    ``RUN/agreement.json``) and returned."""
    from sc2data.rl.train import load_config, play, require_rl

    require_rl("sc2data rl agreement")
    if episodes < 1:
        raise Sc2DataError("--episodes must be at least 1")
    cfg = load_config(run)
    import json

    import torch
    from sb3_contrib import MaskablePPO

    from sc2data.labels.registry import call, load_registry
    from sc2data.model.reward import load_model
    from sc2data.rl.envs import BuildMarinesGym
    from sc2data.rl.rewards import stacks_of
    from sc2data.rulebase import schema_for
    from sc2data.vocab import STEP_MUL

    torch.set_num_threads(1)
    scorer = load_model(mem)
    commands = [c for c in scorer.commands if c.get("id") and c.get("text")]
    if not commands:
        raise Sc2DataError(f"{mem} records no commands (train it with this sc2data version)")
    ids = [str(c["id"]) for c in commands]
    texts = [str(c["text"]) for c in commands]
    registry = load_registry()
    entries = [registry.get(i) for i in ids]  # an unknown id: one line naming the known ones
    rule_schema = schema_for(k for e in entries for k in e.rule.requires if "/" in k)
    limit = scorer.threshold if threshold is None else float(threshold)

    model = MaskablePPO.load(run / "model.zip", device="cpu")
    loops = cfg.episode_steps * STEP_MUL if cfg.episode_steps else None
    env = BuildMarinesGym(cfg.action_space, backend=cfg.backend, obs=cfg.obs_config(),
                          game_loops=loops)
    n = len(ids)
    tp, fp, fn = np.zeros(n, int), np.zeros(n, int), np.zeros(n, int)
    fired_total = np.zeros(n, int)
    stacks = null = null_clean = 0
    marines: list[int] = []
    try:
        for e in range(episodes):
            for info in play(model, env, AGREEMENT_SEED + e, deterministic):
                frames = env.frames
                if len(frames) < 2:
                    continue
                rb = stacks_of(frames, rule_schema)
                fired = np.stack([np.asarray(call(e.rule, e.source, rb, "a policy's stacks"),
                                             bool) for e in entries], axis=1)  # (B, n)
                matched = scorer.distances(stacks_of(frames, scorer.schema), texts) < limit
                tp += (fired & matched).sum(0)
                fp += (~fired & matched).sum(0)
                fn += (fired & ~matched).sum(0)
                fired_total += fired.sum(0)
                none = ~fired.any(1)
                stacks += len(fired)
                null += int(none.sum())
                null_clean += int((none & ~matched.any(1)).sum())
            marines.append(int(info["marines"]))
    finally:
        env.close()
    per = {i: {"text": t, "rule_fired": int(fired_total[k]), "mem_matched": int(tp[k] + fp[k]),
               "tp": int(tp[k]), "fp": int(fp[k]), "fn": int(fn[k]),
               "precision": _ratio(int(tp[k]), int(tp[k] + fp[k])),
               "recall": _ratio(int(tp[k]), int(tp[k] + fn[k]))}
           for k, (i, t) in enumerate(zip(ids, texts))}
    result = {"run": str(run), "mem": str(mem), "episodes": episodes,
              "seeds": [AGREEMENT_SEED + e for e in range(episodes)],
              "deterministic": deterministic, "threshold": limit, "stacks": stacks,
              "marines": marines, "commands": per, "null_stacks": null,
              "null_unmatched": _ratio(null_clean, null),
              "config": cfg.identity()}
    path = out or run / "agreement.json"
    write_atomic(path, (json.dumps(result, indent=1) + "\n").encode())
    return result


def summary(result: dict[str, Any]) -> list[str]:
    """A small table: per command, rule firings, MEM matches, precision and recall."""
    def pct(x: float | None) -> str:
        return "—" if x is None else f"{100 * x:.1f}%"

    lines = [(f"{result['stacks']:,} stacks over {result['episodes']} episodes "
              f"(marines {result['marines']}), threshold {result['threshold']}"),
             (f"{'command':<20} {'rule fired':>10} {'MEM matched':>11} {'precision':>9} "
              f"{'recall':>7}")]
    for cid, c in result["commands"].items():
        lines.append(f"{cid:<20} {c['rule_fired']:>10,} {c['mem_matched']:>11,} "
                     f"{pct(c['precision']):>9} {pct(c['recall']):>7}")
    lines.append(f"null stacks (no rule fires): {result['null_stacks']:,}, matched to no "
                 f"command by the MEM: {pct(result['null_unmatched'])}")
    return lines
