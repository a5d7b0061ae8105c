"""Throughput of the MEM as a reward: states/s of ``MEMScorer.distance`` at batch 1, 8 and 64.

A reinforcement-learning loop calls ``load_model(RUN).distance(stacks, texts)`` once per env step
with one stack per vectorised env (batch = number of envs) and each env's command. This measures
exactly that call, on real stacks of the run's own pair set (all its packed splits, up to
``--pool-states``; consecutive calls get different stacks) and texts drawn from the run's
commands, one per stack. Figures are the median over ``--repeats`` timed repeats of ``--calls``
calls each, after a warm-up; torch's intra-op threads are set with ``torch.set_num_threads``.

``--ref DIR`` also measures another checkout of sc2data (e.g. ``git worktree add --detach DIR
main``) on the same run, in child processes alternated round by round with this checkout, so
that both see the same load on a shared machine; it prints both and their ratio.
``--ref-training-path`` alternates the same way with this checkout's training-path encoder
(``load_model(RUN, fast=False)``), which any checkpoint can be read with.
``--breakdown`` prints where the time of one batch goes.

    python benchmarks/bench_scorer.py RUN                         # CPU, 1 thread
    python benchmarks/bench_scorer.py RUN --threads 1,2 --ref /tmp/sc2data-main
    python benchmarks/bench_scorer.py RUN --device cuda           # on a GPU machine
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def real_stacks(run: Path, limit: int) -> dict[str, np.ndarray]:
    """Up to ``limit`` stacks from the packed splits of the pair set the run was trained on."""
    from sc2data.pairs.loader import PairSet

    data = json.loads((run / "config.json").read_text())["data"]
    ps = PairSet(data)
    parts: list[dict[str, np.ndarray]] = []
    n = 0
    for split in ("test", "val", "train"):
        with ps.packed(split) as packed:
            k = min(len(packed), limit - n)
            if k > 0:
                parts.append(dict(packed.read(0, k).arrays))
                n += k
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


def measure(run: Path, device: str, threads: int, batches: list[int], repeats: int, calls: int,
            pool_states: int, fast: bool = True) -> dict[str, Any]:
    """States/s of ``distance`` per batch size (median over repeats) in this process
    (``fast=False``: through the training path's encoder, ``load_model(run, fast=False)``)."""
    import torch

    import sc2data

    torch.set_num_threads(threads)
    scorer = sc2data.load_model(run, device=device, fast=fast)
    stacks = real_stacks(run, pool_states)
    n = len(next(iter(stacks.values())))
    texts = [c["text"] for c in scorer.commands] or ["build a barracks"]
    rng = np.random.default_rng(0)
    cuda = device.startswith("cuda")
    out: dict[str, Any] = {"threads": torch.get_num_threads(), "states_available": n,
                           "sc2data": str(Path(sc2data.__file__).parents[1]), "rates": {}}
    for b in batches:
        starts = rng.integers(0, max(n - b, 0) + 1, size=calls * (repeats + 1))
        batches_in = [{k: v[s:s + b] for k, v in stacks.items()} for s in starts[:calls]]
        words = [[texts[i] for i in rng.integers(0, len(texts), b)] for _ in range(calls)]
        for x, t in zip(batches_in, words):  # warm-up
            scorer.distance(x, t)
        rates = []
        for _ in range(repeats):
            if cuda:
                torch.cuda.synchronize()
            t0 = time.perf_counter()
            for x, t in zip(batches_in, words):
                scorer.distance(x, t)  # returns numpy: the GPU is synchronised per call
            rates.append(b * calls / (time.perf_counter() - t0))
        out["rates"][str(b)] = rates
    return out


def breakdown(run: Path, device: str, threads: int, batch: int) -> None:
    """Milliseconds per stage of one batch: the reference (training) path, then the scorer."""
    import torch

    import sc2data
    from sc2data.model.mem import model_inputs

    torch.set_num_threads(threads)
    scorer = sc2data.load_model(run, device=device)
    arrays = {k: v[:batch] for k, v in real_stacks(run, batch).items()}
    model = scorer.model
    dev = torch.device(device)

    def ms(f: Any, r: int = 15) -> float:
        f()
        ts = []
        for _ in range(r):
            t0 = time.perf_counter()
            f()
            ts.append(time.perf_counter() - t0)
        return statistics.median(ts) * 1e3

    with torch.inference_mode():
        x = model_inputs(model, arrays, dev)
        rows = [("reference: pack in numpy (model_inputs)", ms(lambda: model_inputs(model,
                                                                                   arrays, dev)))]
        for g, inp in model.state.groups:
            a = (x.get(f"{g}.idx"), x.get(f"{g}.scalar"))
            img = inp(*a)
            rows.append((f"reference: {g} one-hot image",
                         ms(lambda inp=inp, a=a: inp(*a))))
            rows.append((f"reference: {g} CNN",
                         ms(lambda g=g, img=img: model.state.towers[g](img))))
        rows.append(("reference: whole state encoder", ms(lambda: model.state(x))))
        if scorer.fast is not None:  # this checkout's CPU path (sc2data.model.infer)
            for g, grp in scorer.fast.groups:
                rows.append((f"fast: {g} cell counts + CNN", ms(lambda grp=grp: grp(arrays))))
            rows.append(("fast: whole state encoder", ms(lambda: scorer.fast(arrays))))
        rows.append(("text embedding (cached per text)",
                     ms(lambda: scorer.embed_texts(["build a barracks"]))))
    rows.append(("scorer.distance (all of it)", ms(lambda: scorer.distance(arrays,
                                                                           "build a barracks"))))
    print(f"breakdown at batch {batch}, {threads} thread(s), {device}:")
    for name, v in rows:
        print(f"  {name:44s} {v:8.2f} ms")


def child(code: Path | None, args: argparse.Namespace, threads: int, fast: bool = True
          ) -> dict[str, Any]:
    """Run :func:`measure` in a fresh interpreter importing sc2data from ``code``."""
    env = dict(os.environ)
    if code is not None:
        env["PYTHONPATH"] = str(code) + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, __file__, str(args.run), "--worker", "--device", args.device,
           "--threads", str(threads), "--batches", args.batches, "--repeats", str(args.repeats),
           "--calls", str(args.calls), "--pool-states", str(args.pool_states)]
    if not fast:
        cmd.append("--training-path")
    res = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False,
                         cwd="/" if code is not None else None)
    if res.returncode:
        raise SystemExit(f"worker failed ({code or 'this checkout'}):\n{res.stderr}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a run folder of sc2data train")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--threads", default="1", help="torch CPU thread counts to try, e.g. 1,2")
    ap.add_argument("--batches", default="1,8,64")
    ap.add_argument("--repeats", type=int, default=7, help="timed repeats per batch size")
    ap.add_argument("--calls", type=int, default=20, help="calls per timed repeat")
    ap.add_argument("--pool-states", type=int, default=512, help="real stacks to draw from")
    ap.add_argument("--ref", type=Path, help="another sc2data checkout to compare against")
    ap.add_argument("--ref-training-path", action="store_true",
                    help="compare against this checkout's training path (fast=False) instead")
    ap.add_argument("--rounds", type=int, default=3, help="alternations with the reference")
    ap.add_argument("--breakdown", action="store_true")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--training-path", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    batches = [int(b) for b in args.batches.split(",")]

    if args.worker:
        print(json.dumps(measure(args.run, args.device, int(args.threads), batches,
                                 args.repeats, args.calls, args.pool_states,
                                 fast=not args.training_path)))
        return
    print(f"machine: {platform.platform()}, {os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.1f}; run {args.run}; device {args.device}")
    for threads in [int(t) for t in args.threads.split(",")]:
        if args.breakdown:
            breakdown(args.run, args.device, threads, max(batches))
        codes: list[tuple[Path | None, bool]] = [(None, True)]
        if args.ref_training_path:
            codes.append((None, False))
        elif args.ref:
            codes.append((args.ref, True))
        ref = len(codes) > 1
        rates: dict[int, dict[str, list[float]]] = {i: {} for i in range(len(codes))}
        for _ in range(args.rounds if ref else 1):
            for i, (code, fast) in enumerate(codes):
                for b, r in child(code, args, threads, fast)["rates"].items():
                    rates[i].setdefault(b, []).extend(r)
        med = {i: {b: statistics.median(r) for b, r in rs.items()} for i, rs in rates.items()}
        print(f"{args.device}, {threads} torch thread(s): states/s of distance, median of "
              f"{len(rates[0][str(batches[0])])} repeats × {args.calls} calls")
        name = "training path" if args.ref_training_path else "--ref"
        head = "  batch  this checkout" + (f"  {name:>13s}   ratio" if ref else "")
        print(head)
        for b in batches:
            line = f"  {b:5d}  {med[0][str(b)]:13,.0f}"
            if ref:
                line += f"  {med[1][str(b)]:13,.0f}  {med[0][str(b)] / med[1][str(b)]:5.1f}×"
            print(line)


if __name__ == "__main__":
    main()
