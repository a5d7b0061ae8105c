"""Is the MEM's reward right where the agent goes? MEM matches against the rules, on visited states.

The MEM was trained on states a random agent visits; a learning agent visits others. This plays
seeded episodes with a trained policy (``sc2data rl train``), forms every two-frame stack it
passes through (the stacks the reward wrappers score, see :mod:`sc2data.rl.rewards`), and asks
both judges of each command of the MEM's pair set:

* the **rule** (the labelling rule of the command's id, ``rules/``): does the stack show it?
* the **MEM**: is ``distance(stack, command text) < threshold``?

Per command, with the rule as ground truth: ``precision = TP / (TP + FP)`` (of the stacks the
MEM matched, the share the rule also fired on: how often a narration bonus is deserved),
``recall = TP / (TP + FN)`` (of the stacks the rule fired on, the share the MEM matched: how
often a deserved bonus is paid) and their harmonic mean F1, and what its false matches were
(:func:`false_matches`: the stacks where another command's rule fired, or none did — the
confusions a round of the MEM loop must fix). Stacks on which no rule fires are "null" stacks;
the share of them the MEM matches to no command is reported too. Recall is also given on the
stacks where the command's rule is the only one that fired (:func:`recall_alone`): a stack where
two rules fire (an idle SCV sent to mine as a depot appears) is rare in any pair set, and a MEM
that matches only one of its two commands loses recall there, not on the events themselves.
What fired beside each miss is counted (:func:`missed_beside`), beside the distances between the
command texts (:func:`text_distances`): the MEM's distance is Euclidean, so a stack can be within
the threshold of two texts only if they are within twice the threshold of each other — a miss
beside a text farther than that is one the MEM cannot avoid without moving its texts. And
each command's firings are split, in the JSON (``by_action``), by what the policy chose in the
step (:func:`by_action`: the pysc2 function, or the macro): a rule reads two frames and cannot
always tell what the step did (``collect_minerals`` fires when an idle SCV is sent to build as
well as to mine).

On the simulator, both judges are also held to the game's own record (:mod:`sc2data.labels.truth`:
the event that *is* each built-in command, e.g. an idle SCV ordered to mine for "collect
minerals"): per command, the rule's and the MEM's precision and recall against what happened in
the step (``sim`` in the JSON). Agreement with the rules says whether the MEM learnt the rules;
this says whether either pays for the thing the command names, on the policy's own play.

The two rewards, judged as the field judges a learnt reward (Gleave et al. 2021, *Quantifying
differences in reward functions*): a stack's **rules reward** is the number of rules that fire
on it (``--reward rules`` pays ``bonus`` times that), its **narration reward** the number of
commands the MEM matches (``--reward narration`` pays ``bonus`` for the current command's match;
over a narration whose current command is any of them alike, that is the same up to scale). Both
are functions of the transition ``(s, s')``, the stack's two frames. Reported over the visited
transitions: their Pearson correlation, and the **EPIC distance** — each reward canonicalised
(:func:`canonical`) to remove potential shaping, then the Pearson distance
``sqrt((1 − ρ) / 2)`` between the canonical rewards (:func:`pearson_distance`): 0 for rewards
equal up to shaping and positive scale, 1 for opposite ones. The canonicalisation takes its
state distribution ``D_S`` uniform over :data:`EPIC_SUPPORT` visited states and is evaluated on
:data:`EPIC_TRANSITIONS` visited transitions, both drawn with a fixed seed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.progress import bar
from sc2data.ground.vocab import STEP_MUL
from sc2data.rl import runs
from sc2data.rl.runs import check_file_out, write_file

AGREEMENT_SEED = 2_000_000
"""First episode seed of an agreement measurement (neither training's nor evaluation's)."""
EPIC_TRANSITIONS = 512
"""Visited transitions the EPIC distance is evaluated on (drawn evenly over the episodes)."""
EPIC_SUPPORT = 32
"""Visited states the canonicalisation's ``D_S`` is uniform over."""
BATCH = 512
"""Stacks per MEM call when rewards are evaluated on drawn transitions."""

PairReward = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``reward(i, j)``: the reward of the transitions from state ``i[k]`` to state ``j[k]`` (state
indices), shape ``(P,)`` or ``(P, K)`` for K rewards at once."""

def canonical(reward: PairReward, s: np.ndarray, s2: np.ndarray, support: np.ndarray,
              gamma: float) -> np.ndarray:
    """EPIC's canonically shaped reward of the transitions ``(s[k], s2[k])`` (Gleave et al.
    2021, Definition 4.1), with ``D_S`` uniform over the states ``support`` and rewards that do
    not depend on the action:

    ``C(R)(s, s') = R(s, s') + γ E[R(s', S')] − E[R(s, S')] − γ E[R(S, S')]``, ``S, S' ~ D_S``.

    A potential shaping ``γΦ(s') − Φ(s)`` added to R leaves C(R) unchanged."""
    s, s2, support = (np.asarray(a, np.int64) for a in (s, s2, support))
    states = np.unique(np.concatenate([s, s2]))
    n = len(support)
    out_mean = np.asarray(reward(np.repeat(states, n), np.tile(support, len(states))), float)
    out_mean = out_mean.reshape(len(states), n, *out_mean.shape[1:]).mean(axis=1)
    whole = np.asarray(reward(np.repeat(support, n), np.tile(support, n)), float).mean(axis=0)
    at = np.searchsorted(states, s)
    at2 = np.searchsorted(states, s2)
    r = np.asarray(reward(s, s2), float)
    return r + gamma * out_mean[at2] - out_mean[at] - gamma * whole  # type: ignore[no-any-return]


def pearson(a: np.ndarray, b: np.ndarray) -> float | None:
    """Pearson's ρ of two samples; None where either is constant (ρ is undefined)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    da, db = a - a.mean(), b - b.mean()
    na, nb = math.sqrt(float((da * da).sum())), math.sqrt(float((db * db).sum()))
    if na < 1e-12 * max(1.0, float(np.abs(a).max(initial=0))) or \
            nb < 1e-12 * max(1.0, float(np.abs(b).max(initial=0))):
        return None
    return float(np.clip((da * db).sum() / (na * nb), -1.0, 1.0))


def pearson_distance(a: np.ndarray, b: np.ndarray) -> float | None:
    """``sqrt((1 − ρ) / 2)``: 0 for samples equal up to positive affine maps, 1 for opposite."""
    rho = pearson(a, b)
    return None if rho is None else math.sqrt((1.0 - rho) / 2.0)


def epic_distance(reward: PairReward, s: np.ndarray, s2: np.ndarray, support: np.ndarray,
                  gamma: float) -> float | None:
    """The EPIC distance between the two columns of ``reward`` (``(P, 2)``: R_A and R_B), over
    the transitions ``(s, s2)`` and ``D_S`` uniform over ``support``."""
    c = canonical(reward, s, s2, support, gamma)
    return pearson_distance(c[:, 0], c[:, 1])


def _ratio(a: int, b: int) -> float | None:
    return a / b if b else None


def _f1(tp: int, fp: int, fn: int) -> float | None:
    return _ratio(2 * tp, 2 * tp + fp + fn)


def agreement(run: Path, mem: Path, *, episodes: int = 3, deterministic: bool = False,
              threshold: float | None = None, out: Path | None = None,
              progress: bool | None = None) -> dict[str, Any]:
    """Play ``episodes`` episodes of the policy in ``run``; per-command agreement of the MEM in
    ``mem`` with the rules on the stacks visited, and the two rewards' correlation and EPIC
    distance. Written to ``out`` (default ``RUN/agreement.json``) and returned. ``progress``:
    a bar over the episodes (None: as :func:`~sc2data.ground.progress.bar` decides)."""
    from sc2data.rl.train import load_config, require_rl

    require_rl("sc2data rl agreement")
    if episodes < 1:
        raise Sc2DataError("--episodes must be at least 1")
    if out is not None:
        check_file_out(out)
    cfg = load_config(run)
    import json

    import torch

    torch.set_num_threads(1)
    judge = _Judge.load(mem, threshold)
    seen = _play(run, cfg, judge, episodes=episodes, deterministic=deterministic,
                 progress=progress)
    n = len(judge.ids)
    fired = np.concatenate(seen.fired) if seen.fired else np.zeros((0, n), bool)
    matched = np.concatenate(seen.matched) if seen.matched else np.zeros((0, n), bool)

    def both(i: np.ndarray, j: np.ndarray) -> np.ndarray:
        f, m = judge(seen.kept_rule, seen.kept_mem, i, j)
        return np.stack([f.sum(1), m.sum(1)], axis=1).astype(float)

    epic = None
    if seen.drawn:
        s, s2 = (np.array(x) for x in zip(*seen.drawn))
        epic = epic_distance(both, s, s2, np.array(seen.support), cfg.gamma)
    happened = (np.concatenate(seen.happened) if seen.happened and cfg.backend == "sim"
                else None)
    result = _result(judge, fired, matched, epic=epic, seen=seen, cfg=cfg, happened=happened,
                     head={"run": str(run), "mem": str(mem), "episodes": episodes,
                           "seeds": [AGREEMENT_SEED + e for e in range(episodes)],
                           "deterministic": deterministic, "threshold": judge.limit})
    path = out or run / "agreement.json"
    write_file(path, (json.dumps(result, indent=1) + "\n").encode())
    return result


@dataclass
class _Judge:
    """The rules and the MEM of the commands a MEM records, judging stacks by the batch."""

    scorer: Any
    ids: list[str]
    texts: list[str]
    entries: list[Any]
    rule_schema: Any
    limit: float

    @classmethod
    def load(cls, mem: Path, threshold: float | None) -> _Judge:
        """The MEM in ``mem``, its commands and their rules (an unknown id: one line naming the
        known ones); ``threshold`` (default the MEM's own) is its distance for a match."""
        from sc2data.labels.registry import load_registry
        from sc2data.model.scorer import load_model
        from sc2data.rulebase import schema_for

        scorer = load_model(mem)
        commands = [c for c in scorer.commands if c.get("id") and c.get("text")]
        if not commands:
            raise Sc2DataError(f"{mem} records no commands (train it with this sc2data version)")
        ids = [str(c["id"]) for c in commands]
        registry = load_registry()
        entries = [registry.get(i) for i in ids]
        return cls(scorer, ids, [str(c["text"]) for c in commands], entries,
                   schema_for(k for e in entries for k in e.rule.requires if "/" in k),
                   scorer.threshold if threshold is None else float(threshold))

    def __call__(self, rule_frames: list[Any], mem_frames: list[Any], i: np.ndarray,
                 j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(fired (P, n), matched (P, n)) of the stacks (frame i[k], frame j[k])."""
        from sc2data.labels.registry import call
        from sc2data.rulebase import stack

        fired, matched = [], []
        for a in range(0, len(i), BATCH):
            pairs = list(zip(i[a:a + BATCH].tolist(), j[a:a + BATCH].tolist()))
            rb = stack([(rule_frames[p], rule_frames[q]) for p, q in pairs], self.rule_schema)
            fired.append(np.stack([np.asarray(call(e.rule, e.source, rb, "a policy's stacks"),
                                              bool) for e in self.entries], axis=1))
            mb = stack([(mem_frames[p], mem_frames[q]) for p, q in pairs], self.scorer.schema)
            matched.append(self.scorer.distances(mb, self.texts) < self.limit)
        return np.concatenate(fired), np.concatenate(matched)


@dataclass
class _Seen:
    """What the policy's episodes showed: each episode's judged stacks, and the frames, drawn
    transitions and support states of the EPIC sample (indices into the kept frames)."""

    fired: list[np.ndarray] = field(default_factory=list)
    matched: list[np.ndarray] = field(default_factory=list)
    kept_rule: list[Any] = field(default_factory=list)
    kept_mem: list[Any] = field(default_factory=list)
    drawn: list[tuple[int, int]] = field(default_factory=list)
    support: list[int] = field(default_factory=list)
    marines: list[int] = field(default_factory=list)
    actions: list[str] = field(default_factory=list)
    """What the policy chose (``info["action"]``) in the decision each judged stack belongs to."""
    happened: list[np.ndarray] = field(default_factory=list)
    """Per episode, ``(stacks, commands)``: the simulator's record of each command in the step
    (:func:`sc2data.labels.truth.truth`)."""


def _play(run: Path, cfg: Any, judge: _Judge, *, episodes: int, deterministic: bool,
          progress: bool | None = None) -> _Seen:
    """Play the policy's episodes, judge every stack, and draw each episode's share of the EPIC
    sample."""
    from sc2data.labels.truth import truth
    from sc2data.rl.envs import BuildMarinesGym
    from sc2data.rl.train import play

    loops = cfg.episode_steps * STEP_MUL if cfg.episode_steps else None
    env = BuildMarinesGym(cfg.action_space, backend=cfg.backend, obs=cfg.obs_config(),
                          game_loops=loops, merge_waits=cfg.merge_waits,
                          sites=cfg.macro_sites)
    try:
        model = runs.load_model(run, env)
    except BaseException:
        env.close()
        raise
    pick = np.random.default_rng(AGREEMENT_SEED)
    seen = _Seen()
    try:
        with bar(episodes, desc="rl agreement", unit="episode", show=progress) as b:
            for e in range(episodes):
                rule_frames: list[Any] = []
                mem_frames: list[Any] = []
                happened: list[np.ndarray] = []
                for info in play(model, env, AGREEMENT_SEED + e, deterministic):  # noqa: B007
                    new = env.frames if not rule_frames else env.frames[1:]
                    rule_frames += [judge.rule_schema.extract(f) for f in new]
                    mem_frames += [judge.scorer.schema.extract(f) for f in new]
                    happened += [truth(events, judge.ids) for events in env.events]
                    seen.actions += [str(info["action"])] * (len(env.frames) - 1)
                seen.marines.append(int(info["marines"]))
                steps = np.arange(len(rule_frames) - 1)
                if not len(steps):
                    b.update(1)
                    continue
                fired, matched = judge(rule_frames, mem_frames, steps, steps + 1)
                seen.fired.append(fired)
                seen.matched.append(matched)
                seen.happened.append(np.array(happened, bool).reshape(len(steps), len(judge.ids)))
                _sample(seen, rule_frames, mem_frames, steps, pick=pick, episodes=episodes)
                b.update(1)
    finally:
        env.close()
    return seen


def _sample(seen: _Seen, rule_frames: list[Any], mem_frames: list[Any], steps: np.ndarray, *,
            pick: np.random.Generator, episodes: int) -> None:
    """This episode's share of the EPIC sample, its frames kept under new indices."""
    k = min(len(steps), -(-EPIC_TRANSITIONS // episodes))
    m = min(len(rule_frames), -(-EPIC_SUPPORT // episodes))
    ts = np.sort(pick.choice(steps, k, replace=False))
    us = np.sort(pick.choice(len(rule_frames), m, replace=False))
    need = sorted(set(ts.tolist()) | set((ts + 1).tolist()) | set(us.tolist()))
    index = {f: len(seen.kept_rule) + x for x, f in enumerate(need)}
    seen.kept_rule += [rule_frames[f] for f in need]
    seen.kept_mem += [mem_frames[f] for f in need]
    seen.drawn += [(index[t], index[t + 1]) for t in ts.tolist()]
    seen.support += [index[u] for u in us.tolist()]


def false_matches(fired: np.ndarray, matched: np.ndarray, ids: list[str]
                  ) -> dict[str, dict[str, int]]:
    """Per command, what its false matches were: for each other command, the stacks the MEM
    matched to this one where that command's rule fired (a stack may count under several), and
    ``null`` for those where no rule fired — the confusions a MEM loop's pairs must fix."""
    none = ~fired.any(1)
    out: dict[str, dict[str, int]] = {}
    for k, cid in enumerate(ids):
        false = matched[:, k] & ~fired[:, k]
        out[cid] = _beside(false, fired, ids, k)
        if n := int((false & none).sum()):
            out[cid]["null"] = n
    return out


def _beside(rows: np.ndarray, fired: np.ndarray, ids: list[str], k: int) -> dict[str, int]:
    """Of the stacks ``rows``, how many each command but the ``k``-th had its rule fire on (the
    commands with none left out)."""
    counts = {other: int((rows & fired[:, j]).sum()) for j, other in enumerate(ids) if j != k}
    return {c: n for c, n in counts.items() if n}


def recall_alone(fired: np.ndarray, matched: np.ndarray) -> tuple[np.ndarray, list[float | None]]:
    """Per command, the stacks where its rule was the only one that fired, and the share of them
    the MEM matched to it (None where there are none)."""
    alone = fired & (fired.sum(1) == 1)[:, None]
    n = alone.sum(0)
    hit = (alone & matched).sum(0)
    return n, [_ratio(int(h), int(k)) for h, k in zip(hit, n)]


def missed_beside(fired: np.ndarray, matched: np.ndarray, ids: list[str]
                  ) -> dict[str, dict[str, int]]:
    """Per command, what fired beside it where the MEM missed it: for each other command, the
    stacks where both rules fired and the MEM did not match this one (a stack may count under
    several). A stack is within ``threshold`` of two command texts only if the texts are within
    twice that of each other (the triangle inequality), so a miss beside a far text
    (:func:`text_distances`) is one no MEM of these embeddings could avoid."""
    return {cid: _beside(fired[:, k] & ~matched[:, k], fired, ids, k)
            for k, cid in enumerate(ids)}


def text_distances(embeddings: np.ndarray, ids: list[str]) -> dict[str, dict[str, float]]:
    """The Euclidean distance between every two commands' text embeddings (``(n, dim)``)."""
    from sc2data.model.scorer import pairwise

    d = pairwise(embeddings, embeddings)
    return {a: {b: round(float(d[i, j]), 4) for j, b in enumerate(ids) if j != i}
            for i, a in enumerate(ids)}


def by_action(fired: np.ndarray, matched: np.ndarray, actions: np.ndarray
              ) -> dict[str, dict[str, int]]:
    """Where one command's rule fired (``fired``, ``matched``: that command's columns): per
    action the policy chose in the step, the stacks and how many the MEM matched, most
    frequent first."""
    names, counts = np.unique(np.asarray(actions)[fired], return_counts=True)
    order = np.argsort(-counts, kind="stable")
    return {str(names[j]): {"fired": int(counts[j]),
                            "matched": int((matched & fired & (actions == names[j])).sum())}
            for j in order}


def against_record(fired: np.ndarray, matched: np.ndarray, happened: np.ndarray
                   ) -> dict[str, Any]:
    """One command's columns held to the game's record (``happened``): how often it happened,
    and the rule's and the MEM's precision and recall against it."""
    def pr(said: np.ndarray) -> tuple[float | None, float | None]:
        hit = int((said & happened).sum())
        return _ratio(hit, int(said.sum())), _ratio(hit, int(happened.sum()))

    (rp, rr), (mp, mr) = pr(fired), pr(matched)
    return {"happened": int(happened.sum()), "rule_precision": rp, "rule_recall": rr,
            "mem_precision": mp, "mem_recall": mr}


def _result(judge: _Judge, fired: np.ndarray, matched: np.ndarray, *, epic: float | None,
            seen: _Seen, cfg: Any, happened: np.ndarray | None, head: dict[str, Any]
            ) -> dict[str, Any]:
    """``agreement.json``: ``head``, then per command and over all stacks. ``happened``: the
    simulator's record per stack and command (None on the real game)."""
    from sc2data.labels.truth import EVENT_OF

    tp, fp, fn = ((fired & matched).sum(0), (~fired & matched).sum(0),
                  (fired & ~matched).sum(0))
    none = ~fired.any(1)
    confused = false_matches(fired, matched, judge.ids)
    beside = missed_beside(fired, matched, judge.ids)
    n_alone, r_alone = recall_alone(fired, matched)
    actions = np.array(seen.actions, dtype=object)
    per = {i: {"text": t, "rule_fired": int(fired[:, k].sum()),
               "mem_matched": int(tp[k] + fp[k]), "tp": int(tp[k]), "fp": int(fp[k]),
               "fn": int(fn[k]), "precision": _ratio(int(tp[k]), int(tp[k] + fp[k])),
               "recall": _ratio(int(tp[k]), int(tp[k] + fn[k])),
               "f1": _f1(int(tp[k]), int(fp[k]), int(fn[k])),
               "fired_alone": int(n_alone[k]), "recall_alone": r_alone[k],
               "by_action": by_action(fired[:, k], matched[:, k], actions),
               "pearson": pearson(fired[:, k], matched[:, k]), "false_matches": confused[i],
               "missed_beside": beside[i],
               "sim": (against_record(fired[:, k], matched[:, k], happened[:, k])
                       if happened is not None and i in EVENT_OF else None)}
           for k, (i, t) in enumerate(zip(judge.ids, judge.texts))}
    return {**head, "stacks": int(len(fired)),
            "marines": seen.marines, "commands": per, "null_stacks": int(none.sum()),
            "null_unmatched": _ratio(int((none & ~matched.any(1)).sum()), int(none.sum())),
            "text_distances": text_distances(judge.scorer.embed_texts(judge.texts), judge.ids),
            "reward": {"pearson": pearson(fired.sum(1), matched.sum(1)), "epic": epic,
                       "gamma": cfg.gamma, "epic_transitions": len(seen.drawn),
                       "epic_support": len(seen.support)},
            "config": cfg.identity()}


def summary(result: dict[str, Any]) -> list[str]:
    """A small table: per command, rule firings, MEM matches, precision, recall, F1 and recall
    where its rule was the only one to fire; what the false matches were, and what fired beside
    its misses (marked where the two texts are too far apart for one stack to match both); on
    the simulator, the rule and the MEM against the game's record; then the two rewards'
    correlation and EPIC distance."""
    def pct(x: float | None) -> str:
        return "—" if x is None else f"{100 * x:.1f}%"

    def num(x: float | None) -> str:
        return "—" if x is None else f"{x:.3f}"

    lines = [(f"{result['stacks']:,} stacks over {result['episodes']} episodes "
              f"(marines {result['marines']}), threshold {result['threshold']}"),
             (f"{'command':<20} {'rule fired':>10} {'MEM matched':>11} {'precision':>9} "
              f"{'recall':>7} {'F1':>7} {'recall, only rule':>17}")]
    for cid, c in result["commands"].items():
        lines.append(f"{cid:<20} {c['rule_fired']:>10,} {c['mem_matched']:>11,} "
                     f"{pct(c['precision']):>9} {pct(c['recall']):>7} {pct(c.get('f1')):>7} "
                     f"{pct(c.get('recall_alone')):>17}")
    for cid, c in result["commands"].items():
        if c.get("false_matches"):
            lines.append(f"{cid} matched where instead: " + ", ".join(
                f"{other} fired {n:,}" if other != "null" else f"no rule fired {n:,}"
                for other, n in c["false_matches"].items()))
    far = result.get("text_distances", {})
    for cid, c in result["commands"].items():
        if c.get("missed_beside"):
            parts = []
            for other, n in c["missed_beside"].items():
                d = far.get(cid, {}).get(other, 0.0)
                parts.append(f"{other} {n:,}" + (
                    f" (texts {d:.2f} apart ≥ 2 × threshold: no stack matches both)"
                    if d >= 2 * result["threshold"] else ""))
            lines.append(f"{cid} missed where also fired: " + ", ".join(parts))
    record = {cid: c["sim"] for cid, c in result["commands"].items() if c.get("sim")}
    if record:
        lines.append(f"{'against the game':<20} {'happened':>10} {'rule P':>9} {'rule R':>7} "
                     f"{'MEM P':>7} {'MEM R':>7}")
        for cid, r in record.items():
            lines.append(f"{cid:<20} {r['happened']:>10,} {pct(r['rule_precision']):>9} "
                         f"{pct(r['rule_recall']):>7} {pct(r['mem_precision']):>7} "
                         f"{pct(r['mem_recall']):>7}")
    lines.append(f"null stacks (no rule fires): {result['null_stacks']:,}, matched to no "
                 f"command by the MEM: {pct(result['null_unmatched'])}")
    r = result.get("reward")
    if r:
        lines.append(f"narration vs rules reward: Pearson {num(r['pearson'])}, EPIC distance "
                     f"{num(r['epic'])} (γ {r['gamma']}, {r['epic_transitions']} transitions, "
                     f"D_S over {r['epic_support']} states)")
    return lines
