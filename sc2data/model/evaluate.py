"""Evaluate a trained MEM: ``sc2data evaluate RUN`` (metrics, RUN/eval.json) and ``sc2data tsne``.

Metrics, per split, all at the paper's decision rule (match ⇔ distance < 0.5):

- pair accuracy, overall, per command and per pair kind (matched / mismatched / null);
- ROC-AUC of −distance for "matched" (scikit-learn's if installed, else :func:`roc_auc`);
- command retrieval: for each state, the nearest of the canonical commands, or "none" when every
  distance is ≥ 0.5, against the command it satisfies ("none" for a null state);
- paraphrases (evaluation only, never trained on): every test pair re-scored with its command's
  text replaced by each held-out paraphrase; and whether each paraphrase's embedding lies nearest
  its own canonical command (the paper's unmeasured claim).

Each state and each text is embedded once; pair distances are gathered from those embeddings.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.errors import Sc2DataError
from sc2data.model.reward import MEMScorer, load_model, pairwise
from sc2data.pairs.loader import PairSet
from sc2data.vocab import SPLITS

PAPER = {"train": 0.9561, "val": 0.8235, "test": 0.8040}
"""The paper's accuracies (Waytowich et al. 2019, §4)."""


def accuracy(distance: np.ndarray, target: np.ndarray, threshold: float = 0.5) -> float:
    """Share of pairs where (distance < threshold) agrees with (target is a match, y = 0)."""
    if len(distance) == 0:
        return float("nan")
    return float(np.mean((distance < threshold) == (target < 0.5)))


def roc_auc(score: np.ndarray, positive: np.ndarray) -> float:
    """Area under the ROC curve by ranks (Mann–Whitney U), ties counted half."""
    score, positive = np.asarray(score, float), np.asarray(positive, bool)
    n_pos, n_neg = int(positive.sum()), int((~positive).sum())
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    order = np.argsort(score, kind="mergesort")
    ranks = np.empty(len(score))
    s = score[order]
    i = 0
    while i < len(s):  # average rank over each run of ties
        j = i
        while j + 1 < len(s) and s[j + 1] == s[i]:
            j += 1
        ranks[order[i:j + 1]] = (i + j) / 2 + 1
        i = j + 1
    return float((ranks[positive].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def auc(score: np.ndarray, positive: np.ndarray) -> float:
    """ROC-AUC: scikit-learn's when installed, else :func:`roc_auc`."""
    positive = np.asarray(positive, bool)
    if positive.all() or not positive.any():
        return float("nan")
    try:
        from sklearn.metrics import roc_auc_score
    except ImportError:
        return roc_auc(score, positive)
    return float(roc_auc_score(positive, score))


def _embed_split(scorer: MEMScorer, data: PairSet, split: str) -> np.ndarray:
    with data.packed(split) as packed:
        parts = [scorer.embed_states(b) for _, b in packed.blocks(keys=scorer.model.state.keys())]
    return np.concatenate(parts) if parts else np.zeros((0, scorer.model.cfg.dim), np.float32)


def _grouped(d: np.ndarray, target: np.ndarray, groups: np.ndarray, thr: float
             ) -> dict[str, dict[str, float]]:
    return {str(g): {"accuracy": accuracy(d[groups == g], target[groups == g], thr),
                     "pairs": int((groups == g).sum())} for g in np.unique(groups)}


def evaluate(run: str | os.PathLike[str], data: str | os.PathLike[str] | None = None,
             device: str = "auto", allow_unfinished: bool = False) -> dict[str, Any]:
    """Compute every metric for ``run`` on its pair set (or ``data``); write RUN/eval.json."""
    run = Path(run)
    scorer = load_model(run, device, allow_unfinished=allow_unfinished)
    pairset = _pairset(scorer, data)
    thr = scorer.threshold
    ids = [str(c["id"]) for c in pairset.commands]
    canon = pairset.texts()
    canon_e = scorer.embed_texts([canon[i] for i in ids])
    report: dict[str, Any] = {"run": str(run), "data": str(pairset.path),
                              "data_fingerprint": pairset.fingerprint,
                              "same_data_as_training":
                                  pairset.fingerprint == scorer.meta.get("data_fingerprint"),
                              "threshold": thr, "paper": PAPER, "splits": {}}
    for split in SPLITS:
        pairs = pairset.pairs(split)
        if len(pairs) == 0:
            continue
        states = _embed_split(scorer, pairset, split)
        texts = sorted(set(pairs.command.tolist()))
        text_e = scorer.embed_texts(texts)
        which = np.searchsorted(texts, pairs.command)
        d = np.linalg.norm(states[pairs.state] - text_e[which], axis=-1)
        r: dict[str, Any] = {
            "pairs": len(pairs), "accuracy": accuracy(d, pairs.target, thr),
            "roc_auc": auc(-d, pairs.target < 0.5),
            "per_kind": _grouped(d, pairs.target, pairs.kind, thr),
            "per_command": _grouped(d, pairs.target, pairs.command_id, thr),
        }
        r["retrieval"] = _retrieval(states, pairs, canon_e, ids, thr)
        if split == "test":
            r["paraphrases"] = _paraphrases(scorer, states, pairs, pairset, canon_e, ids, thr)
        report["splits"][split] = r
    (run / "eval.json").write_text(json.dumps(report, indent=2))
    return report


def _pairset(scorer: MEMScorer, data: str | os.PathLike[str] | None) -> PairSet:
    if data is None:
        data = scorer.meta.get("config", {}).get("data")
        if data is None:
            raise Sc2DataError("the run does not record its data folder; pass --data DATA")
    pairset = PairSet(Path(data))
    if pairset.schema != scorer.schema:
        raise Sc2DataError(f"{pairset.path} has another state schema than the model; evaluate "
                           f"on data built with the model's layers")
    return pairset


def _retrieval(states: np.ndarray, pairs: Any, canon_e: np.ndarray, ids: list[str],
               thr: float) -> dict[str, Any]:
    """Nearest canonical command (or "none") per state, against the command it satisfies."""
    rows, first = np.unique(pairs.state, return_index=True)
    truth = np.array([lbl if lbl else "none" for lbl in pairs.label[first]])
    dist = pairwise(states[rows], canon_e)
    nearest = np.array(ids)[dist.argmin(1)]
    pred = np.where(dist.min(1) < thr, nearest, "none")
    classes = ids + ["none"]
    return {"states": len(rows), "accuracy": float(np.mean(pred == truth)),
            "per_class": {c: {"accuracy": float(np.mean(pred[truth == c] == c))
                              if (truth == c).any() else float("nan"),
                              "states": int((truth == c).sum())} for c in classes},
            "confusion": {c: {p: int(((truth == c) & (pred == p)).sum()) for p in classes}
                          for c in classes}}


def _paraphrases(scorer: MEMScorer, states: np.ndarray, pairs: Any, pairset: PairSet,
                 canon_e: np.ndarray, ids: list[str], thr: float) -> dict[str, Any]:
    """Test pairs re-scored with each paraphrase; and each paraphrase's nearest canonical text."""
    per: dict[str, Any] = {}
    correct = total = near = 0
    for cid, texts in pairset.paraphrases().items():
        mask = pairs.command_id == cid
        for text in texts:
            e = scorer.embed_texts([text])
            d = np.linalg.norm(states[pairs.state[mask]] - e, axis=-1)
            acc = accuracy(d, pairs.target[mask], thr)
            hits = int(((d < thr) == (pairs.target[mask] < 0.5)).sum())
            nearest = ids[int(pairwise(e, canon_e)[0].argmin())]
            per[text] = {"command_id": cid, "accuracy": acc, "pairs": int(mask.sum()),
                         "nearest_command": nearest}
            correct += hits
            total += int(mask.sum())
            near += nearest == cid
    return {"accuracy": correct / total if total else float("nan"),
            "nearest_is_own_command": near / len(per) if per else float("nan"),
            "per_paraphrase": per}


def format_report(report: dict[str, Any]) -> str:
    """The printed table: our accuracy per split beside the paper's, then the details."""
    pct = lambda x: "   n/a" if x != x else f"{100 * x:6.2f}"  # noqa: E731  (NaN-safe)
    lines = [f"{'split':<6} {'pairs':>7} {'accuracy %':>11} {'paper %':>8} {'ROC-AUC':>8} "
             f"{'retrieval %':>12}"]
    for split, r in report["splits"].items():
        lines.append(f"{split:<6} {r['pairs']:>7} {pct(r['accuracy']):>11} "
                     f"{pct(report['paper'][split]):>8} {r['roc_auc']:>8.4f} "
                     f"{pct(r['retrieval']['accuracy']):>12}")
    test = report["splits"].get("test")
    if test:
        lines.append("test per kind:    " + "  ".join(
            f"{k} {pct(v['accuracy']).strip()}% ({v['pairs']})"
            for k, v in test["per_kind"].items()))
        lines.append("test per command: " + "  ".join(
            f"{k} {pct(v['accuracy']).strip()}%" for k, v in test["per_command"].items()))
        retrieval = test["retrieval"]["per_class"]
        lines.append("test retrieval:   " + "  ".join(
            f"{k} {pct(v['accuracy']).strip()}%" for k, v in retrieval.items()))
        p = test.get("paraphrases")
        if p and p["per_paraphrase"]:
            lines.append(f"test paraphrases: accuracy {pct(p['accuracy']).strip()}%, nearest to "
                         f"their own command {pct(p['nearest_is_own_command']).strip()}%")
            for text, v in p["per_paraphrase"].items():
                lines.append(f"  {text!r:<34} {pct(v['accuracy'])}%  nearest: "
                             f"{v['nearest_command']}")
    if not report["same_data_as_training"]:
        lines.append("note: evaluated on data other than the training data (fingerprints differ)")
    return "\n".join(lines)


def tsne(run: str | os.PathLike[str], data: str | os.PathLike[str] | None = None,
         out: str | os.PathLike[str] | None = None, states: int = 2000, seed: int = 0,
         texts: Sequence[str] = (), device: str = "auto", allow_unfinished: bool = False) -> Path:
    """Plot test-state and command embeddings in one t-SNE map (the paper's Fig. 3) as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    run = Path(run)
    scorer = load_model(run, device, allow_unfinished=allow_unfinished)
    pairset = _pairset(scorer, data)
    split = "test" if len(pairset.pairs("test")) else "val"
    pairs = pairset.pairs(split)
    rows, first = np.unique(pairs.state, return_index=True)
    labels = pairs.label[first]
    rng = np.random.default_rng(seed)
    pick = np.sort(rng.permutation(len(rows))[:states])
    rows, labels = rows[pick], labels[pick]
    emb = _embed_split(scorer, pairset, split)[rows]
    ids = [str(c["id"]) for c in pairset.commands]
    canon = pairset.texts()
    marks = [(canon[i], i, "canonical") for i in ids]
    marks += [(p, i, "paraphrase") for i, ps in pairset.paraphrases().items() for p in ps]
    marks += [(t, "", "extra") for t in texts]
    text_e = scorer.embed_texts([m[0] for m in marks])
    xy = _tsne(np.concatenate([emb, text_e]), seed)
    s_xy, t_xy = xy[:len(emb)], xy[len(emb):]

    fig, ax = plt.subplots(figsize=(11, 9))
    colours = {cid: plt.get_cmap("tab10")(k) for k, cid in enumerate(ids)}
    null = labels == ""
    ax.scatter(s_xy[null, 0], s_xy[null, 1], s=6, c="lightgrey",
               label=f"null ({int(null.sum())})")
    for cid in ids:
        m = labels == cid
        ax.scatter(s_xy[m, 0], s_xy[m, 1], s=8, color=colours[cid], alpha=0.7,
                   label=f"{canon[cid]} ({int(m.sum())})")
    style = {"canonical": ("*", 420), "paraphrase": ("D", 90), "extra": ("X", 160)}
    notes = []
    for (text, cid, kind), (x, y) in zip(marks, t_xy):
        marker, size = style[kind]
        ax.scatter([x], [y], marker=marker, s=size, color=colours.get(cid, "black"),
                   edgecolors="black", linewidths=1.2, zorder=5)
        notes.append(ax.annotate(
            text, (x, y), xytext=(10, 6), textcoords="offset points", zorder=6,
            fontsize=9 if kind == "canonical" else 7,
            fontweight="bold" if kind == "canonical" else "normal",
            arrowprops=dict(arrowstyle="-", lw=0.6, color="0.3"),
            bbox=dict(boxstyle="round,pad=0.2", fc="white", alpha=0.8, lw=0)))
    for kind, (marker, _) in style.items():
        if any(m[2] == kind for m in marks):
            ax.scatter([], [], marker=marker, color="white", edgecolors="black",
                       label=f"{kind} command")
    ax.legend(loc="best", fontsize=8, markerscale=1.5)
    ax.set_title(f"MEM embedding space, t-SNE of {len(emb)} {split} states and "
                 f"{len(marks)} commands ({run.name})")
    ax.set_xticks([])
    ax.set_yticks([])
    path = Path(out) if out else run / "tsne.png"
    fig.tight_layout()
    _declutter(fig, notes)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def _declutter(fig: Any, notes: list[Any]) -> None:
    """Move command labels apart: right or left of the mark, stepping up or down, until a label
    overlaps no earlier one and stays inside the axes."""
    from matplotlib.text import Text

    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    if not notes:
        return
    frame = notes[0].axes.get_window_extent(renderer)
    steps = [0] + [d * k for k in range(1, 16) for d in (-1, 1)]
    placed: list[Any] = []

    def put(note: Any, side: str, dy: float) -> Any:
        note.set_position((10, dy) if side == "right" else (-10, dy))
        note.set_horizontalalignment("left" if side == "right" else "right")
        return Text.get_window_extent(note, renderer)  # the text alone, not its arrow

    for note in notes:
        best = None  # (overlaps, side, dy) of the least crowded spot inside the axes
        for side, dy in [(side, 6 + 10 * k) for k in steps for side in ("right", "left")]:
            box = put(note, side, dy)
            if not (box.x0 >= frame.x0 and box.x1 <= frame.x1 and box.y0 >= frame.y0
                    and box.y1 <= frame.y1):
                continue
            crowd = sum(box.overlaps(b) for b in placed)
            if best is None or crowd < best[0]:
                best = (crowd, side, dy)
            if crowd == 0:
                break
        placed.append(put(note, best[1], best[2]) if best else put(note, "right", 6))


def _tsne(x: np.ndarray, seed: int) -> np.ndarray:
    """2-d t-SNE: openTSNE if installed (faster), else scikit-learn's."""
    perplexity = float(max(2, min(30, (len(x) - 1) // 3)))
    try:
        from openTSNE import TSNE

        return np.asarray(TSNE(perplexity=perplexity, random_state=seed, n_jobs=2,
                               verbose=False).fit(x))
    except ImportError:
        from sklearn.manifold import TSNE as SkTSNE

        return SkTSNE(perplexity=perplexity, random_state=seed, init="pca").fit_transform(x)
