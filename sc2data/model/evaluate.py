"""Evaluate a trained MEM: ``sc2data evaluate RUN`` (metrics, RUN/eval.json) and ``sc2data tsne``.

Metrics, per split, all at the paper's decision rule (match ⇔ distance < 0.5):

- pair accuracy, overall, per command and per pair kind (matched / mismatched / null);
- ROC-AUC of −distance for "matched" (scikit-learn's if installed, else :func:`roc_auc`);
- command retrieval: for each state, the nearest of the canonical commands, or "none" when every
  distance is ≥ 0.5, against the command it satisfies ("none" for a null state);
- phrasings, on the test split: every test pair of a command re-scored with its text replaced by
  another phrase of that command — the recipe's held-out ``paraphrases`` (never trained on: the
  paper's unmeasured claim that a synonym changes nothing), its ``train_paraphrases`` (seen in
  training, on other states), and any ``--text "PHRASE=command_id"`` a user gives — beside the
  canonical text on the same pairs. Per phrase: *balanced* accuracy, the mean of the accuracy on
  its matched pairs and on its mismatched and null pairs (a third of a command's test pairs match,
  so plain accuracy would reward a phrase that matches nothing), plain accuracy, and the nearest
  canonical command to its embedding. Per group: the mean over phrases and the worst phrase.

Each state and each text is embedded once; pair distances are gathered from those embeddings.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import check_out, write_atomic
from sc2data.ground.progress import bar as progress_bar
from sc2data.ground.vocab import SPLITS
from sc2data.model.runs import EVAL, TSNE
from sc2data.model.scorer import MEMScorer, load_model, pairwise
from sc2data.pairs.loader import PairSet

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


def _embed_split(scorer: MEMScorer, data: PairSet, split: str,
                 progress: bool | None = None) -> np.ndarray:
    """Every packed state of ``split`` through the state encoder, with a progress bar."""
    parts = []
    with data.packed(split) as packed, \
            progress_bar(len(packed), desc=f"embed {split}", unit="state", show=progress) as bar:
        for _, b in packed.blocks(keys=scorer.model.state.keys()):
            parts.append(scorer.embed_states(b))
            bar.update(len(parts[-1]))
    return np.concatenate(parts) if parts else np.zeros((0, scorer.model.cfg.dim), np.float32)


def _grouped(d: np.ndarray, target: np.ndarray, groups: np.ndarray, thr: float
             ) -> dict[str, dict[str, float]]:
    return {str(g): {"accuracy": accuracy(d[groups == g], target[groups == g], thr),
                     "pairs": int((groups == g).sum())} for g in np.unique(groups)}


def parse_text_option(value: str, ids: Sequence[str]) -> tuple[str, str]:
    """``"PHRASE=command_id"`` → (phrase, command id); anything else is a one-line error."""
    phrase, sep, cid = value.rpartition("=")
    phrase, cid = phrase.strip(), cid.strip()
    if not sep or not phrase:
        raise Sc2DataError(f"--text {value!r}: give PHRASE=command_id, e.g. "
                           f"\"make a worker={ids[0] if ids else 'build_scv'}\"")
    if cid not in ids:
        raise Sc2DataError(f"--text {value!r}: unknown command id {cid!r}; the pair set's "
                           f"commands are {', '.join(ids)}")
    return phrase, cid


def evaluate(run: str | os.PathLike[str], data: str | os.PathLike[str] | None = None, *,
             device: str = "auto", texts: Sequence[str] = (),
             allow_unfinished: bool = False, other_data: bool = False,
             progress: bool | None = None) -> dict[str, Any]:
    """Compute every metric for ``run`` on its pair set (or ``data``); write RUN/eval.json.

    ``texts`` are extra phrasings to measure, each ``"PHRASE=command_id"``. A pair set other than
    the one the run was trained on (another pair-set fingerprint: re-split or re-drawn, so its
    test split may hold training states) is refused unless ``other_data``; its report then goes
    to ``RUN/eval-<fingerprint>.json`` and the run's own ``eval.json`` is kept. ``progress``: a
    bar per split embedded (see :func:`sc2data.ground.progress.bar`).
    """
    run = Path(run)
    scorer = load_model(run, device, allow_unfinished=allow_unfinished)
    pairset = _pairset(scorer, data)
    own = pairset.pairset_fingerprint == scorer.meta.get("data_fingerprint")
    if not own and not other_data:
        raise Sc2DataError(f"{pairset.path} is not the pair set {run} was trained on (another "
                           f"fingerprint: its test split may hold training states); pass "
                           f"--other-data to evaluate on it anyway")
    command_ids = [str(c["id"]) for c in pairset.commands]
    extra = [parse_text_option(t, command_ids) for t in texts]
    scorer.embed_texts([p for p, _ in extra])  # a phrase the encoder cannot read fails now
    thr = scorer.threshold
    ids = [str(c["id"]) for c in pairset.commands]
    canon = pairset.texts()
    canon_e = scorer.embed_texts([canon[i] for i in ids])
    report: dict[str, Any] = {"run": str(run), "data": str(pairset.path),
                              "data_fingerprint": pairset.pairset_fingerprint,
                              "same_data_as_training": own,
                              "threshold": thr, "paper": PAPER, "splits": {}}
    for split in SPLITS:
        pairs = pairset.pairs(split)
        if len(pairs) == 0:
            continue
        states = _embed_split(scorer, pairset, split, progress)
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
            r["phrasings"] = _phrasings(scorer, states, pairs, pairset, canon_e, ids, extra, thr)
        report["splits"][split] = r
    report["written_to"] = str(report_path(run, pairset.pairset_fingerprint, own))
    write_atomic(Path(report["written_to"]), json.dumps(report, indent=2).encode())
    return report


def report_path(run: Path, pairset_fingerprint: str, own: bool) -> Path:
    """``RUN/eval.json`` for the run's own pair set, else ``RUN/eval-<f[:12]>.json`` for the
    pair-set fingerprint ``f``."""
    return run / (EVAL if own else f"eval-{pairset_fingerprint[:12]}.json")


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


PHRASE_GROUPS = {"held_out": "held-out paraphrases", "training": "training phrasings",
                 "extra": "--text phrasings"}
"""Groups of phrasings the report measures, and how it names them."""


def _phrase_scores(d: np.ndarray, target: np.ndarray, thr: float) -> dict[str, float]:
    pos = target < 0.5
    tpr = float(np.mean(d[pos] < thr)) if pos.any() else float("nan")
    tnr = float(np.mean(d[~pos] >= thr)) if (~pos).any() else float("nan")
    return {"balanced_accuracy": float(np.nanmean([tpr, tnr])) if pos.any() or (~pos).any()
            else float("nan"),
            "matched_accuracy": tpr, "other_accuracy": tnr, "accuracy": accuracy(d, target, thr)}


def _phrasings(scorer: MEMScorer, states: np.ndarray, pairs: Any, pairset: PairSet,
               canon_e: np.ndarray, ids: list[str], extra: Sequence[tuple[str, str]],
               thr: float) -> dict[str, Any]:
    """Test pairs of each command re-scored with each of its phrasings, beside its canonical
    text; per group the mean balanced accuracy over phrases and the worst phrase."""
    canon = pairset.texts()
    groups = {"held_out": [(p, c) for c, ps in pairset.paraphrases().items() for p in ps],
              "training": [(p, c) for c, ps in pairset.train_paraphrases().items() for p in ps],
              "extra": list(extra)}
    out: dict[str, Any] = {"canonical": {}}
    for cid in ids:
        mask = pairs.command_id == cid
        d = np.linalg.norm(states[pairs.state[mask]] - canon_e[ids.index(cid)], axis=-1)
        out["canonical"][cid] = {"text": canon[cid], "pairs": int(mask.sum()),
                                 **_phrase_scores(d, pairs.target[mask], thr)}
    for group, phrases in groups.items():
        per: dict[str, Any] = {}
        for text, cid in phrases:
            mask = pairs.command_id == cid
            e = scorer.embed_texts([text])
            d = np.linalg.norm(states[pairs.state[mask]] - e, axis=-1)
            per[text] = {"command_id": cid, "pairs": int(mask.sum()),
                         **_phrase_scores(d, pairs.target[mask], thr),
                         "canonical_balanced_accuracy":
                             out["canonical"][cid]["balanced_accuracy"],
                         "nearest_command": ids[int(pairwise(e, canon_e)[0].argmin())]}
        scores = {t: v["balanced_accuracy"] for t, v in per.items()
                  if v["balanced_accuracy"] == v["balanced_accuracy"]}
        worst = min(scores, key=scores.__getitem__) if scores else None
        out[group] = {
            "phrases": len(per),
            "mean_balanced_accuracy": float(np.mean(list(scores.values()))) if scores
            else float("nan"),
            "worst": {"text": worst, "balanced_accuracy": scores[worst]} if worst else None,
            "nearest_is_own_command": float(np.mean([v["nearest_command"] == v["command_id"]
                                                     for v in per.values()])) if per
            else float("nan"),
            "per_phrase": per}
    return out


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
        lines.extend(_format_phrasings(test.get("phrasings"), pct))
    if not report["same_data_as_training"]:
        lines.append("note: evaluated on data other than the training data (fingerprints differ)")
    return "\n".join(lines)


def _format_phrasings(p: dict[str, Any] | None, pct: Any) -> list[str]:
    """The phrasing lines of the report: canonical, then each non-empty group, phrase by phrase."""
    if not p:
        return []
    canon = p["canonical"]
    lines = ["test phrasings (balanced accuracy: matched and other pairs weighted equally):",
             "  canonical:  " + "  ".join(f"{c} {pct(v['balanced_accuracy']).strip()}%"
                                          for c, v in canon.items())]
    for group, title in PHRASE_GROUPS.items():
        g = p.get(group)
        if not g or not g["per_phrase"]:
            continue
        worst = g["worst"]
        lines.append(f"  {title}: mean {pct(g['mean_balanced_accuracy']).strip()}%, worst "
                     + (f"{worst['text']!r} {pct(worst['balanced_accuracy']).strip()}%"
                        if worst else "n/a")
                     + f", nearest to their own command "
                       f"{pct(g['nearest_is_own_command']).strip()}%")
        for text, v in g["per_phrase"].items():
            lines.append(f"    {text!r:<28} {v['command_id']:<19} {pct(v['balanced_accuracy'])}%"
                         f"  (canonical {pct(v['canonical_balanced_accuracy']).strip()}%)  "
                         f"nearest: {v['nearest_command']}")
    return lines


SEPARATED = 0.5
"""Below this share of command states lying nearest their own command, the t-SNE picture says
that the model has not separated the commands (whatever clusters t-SNE draws)."""


def separation_note(states: np.ndarray, labels: np.ndarray, commands: np.ndarray,
                    ids: Sequence[str]) -> str | None:
    """A warning for the picture when, in the embedding space itself, fewer than
    :data:`SEPARATED` of the labelled states lie nearest their own command's embedding."""
    own = labels != ""
    if not own.any() or len(ids) < 2:
        return None
    nearest = np.asarray(ids)[pairwise(states[own], commands).argmin(1)]
    share = float((nearest == labels[own]).mean())
    if share >= SEPARATED:
        return None
    return (f"this model has not separated the commands: {share:.0%} of the command states lie "
            f"nearest their own command (chance {1 / len(ids):.0%})")


def tsne(run: str | os.PathLike[str], data: str | os.PathLike[str] | None = None, *,
         out: str | os.PathLike[str] | None = None, states: int = 2000, seed: int = 0,
         texts: Sequence[str] = (), device: str = "auto", allow_unfinished: bool = False,
         progress: bool | None = None) -> Path:
    """Plot test-state and command embeddings in one t-SNE map (the paper's Fig. 3) as a PNG."""
    if out is not None:
        check_out(Path(out))
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
    emb = _embed_split(scorer, pairset, split, progress)[rows]
    ids = [str(c["id"]) for c in pairset.commands]
    marks = _marks(pairset, ids, texts)
    text_e = scorer.embed_texts([m[0] for m in marks])
    warning = separation_note(emb, labels, text_e[:len(ids)], ids)
    xy = _tsne(np.concatenate([emb, text_e]), seed)
    title = (f"MEM embedding space, t-SNE of {len(emb)} {split} states and "
             f"{len(marks)} commands ({run.name})")
    png = _draw_tsne(xy[:len(emb)], labels, xy[len(emb):], marks, canon=pairset.texts(),
                     ids=ids, title=title, warning=warning)
    path = Path(out) if out else run / TSNE
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, png)
    except OSError as e:
        raise Sc2DataError(f"cannot write {path}: {e.strerror or e}; choose another --out") \
            from None
    return path


def _marks(pairset: PairSet, ids: list[str], texts: Sequence[str]) -> list[tuple[str, str, str]]:
    """(text, command id, kind) of every command phrasing drawn: canonical, training phrasings,
    held-out paraphrases, and ``--text`` phrases ("PHRASE=command_id" is coloured as its
    command; a bare phrase in black)."""
    canon = pairset.texts()
    marks = [(canon[i], i, "canonical") for i in ids]
    marks += [(p, i, "training phrasing") for i, ps in pairset.train_paraphrases().items()
              for p in ps]
    marks += [(p, i, "held-out paraphrase") for i, ps in pairset.paraphrases().items() for p in ps]
    for t in texts:
        marks.append((*parse_text_option(t, ids), "extra") if "=" in t else (t, "", "extra"))
    return marks


def _draw_tsne(s_xy: np.ndarray, labels: np.ndarray, t_xy: np.ndarray,
               marks: list[tuple[str, str, str]], *, canon: dict[str, str], ids: list[str],
               title: str, warning: str | None) -> bytes:
    """The t-SNE map as PNG bytes: states coloured by command (null in grey), each phrasing a
    labelled mark."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(11, 9))
    colours = {cid: plt.get_cmap("tab10")(k) for k, cid in enumerate(ids)}
    null = labels == ""
    ax.scatter(s_xy[null, 0], s_xy[null, 1], s=6, c="lightgrey",
               label=f"null ({int(null.sum())})")
    for cid in ids:
        m = labels == cid
        ax.scatter(s_xy[m, 0], s_xy[m, 1], s=8, color=colours[cid], alpha=0.7,
                   label=f"{canon[cid]} ({int(m.sum())})")
    style = {"canonical": ("*", 420), "training phrasing": ("o", 90),
             "held-out paraphrase": ("D", 90), "extra": ("X", 160)}
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
            name = {"canonical": "canonical command", "extra": "--text phrase"}.get(kind, kind)
            ax.scatter([], [], marker=marker, color="white", edgecolors="black", label=name)
    ax.legend(loc="best", fontsize=8, markerscale=1.5)
    ax.set_title(title)
    if warning:
        ax.text(0.5, 0.98, warning, transform=ax.transAxes, ha="center", va="top", fontsize=11,
                color="darkred", zorder=7,
                bbox={"boxstyle": "round", "facecolor": "white", "edgecolor": "darkred"})
    ax.set_xticks([])
    ax.set_yticks([])
    fig.tight_layout()
    _declutter(fig, notes)
    png = io.BytesIO()
    fig.savefig(png, format="png", dpi=130)
    plt.close(fig)
    return png.getvalue()


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
