"""``sc2data rl …``: train, evaluate, compare and plot narration-guided (or unshaped) agents.

Heavy packages (gymnasium, stable-baselines3, torch) are imported inside the commands, so
``sc2data --help`` stays fast and a missing ``rl`` extra is a one-line error naming it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

app = typer.Typer(help="Reinforcement learning on BuildMarines: sparse, rule-shaped or "
                       "narration-shaped rewards (MaskablePPO).",
                  no_args_is_help=True, rich_markup_mode=None)


@app.command("train")
def train_cmd(
    out: Path = typer.Option(..., "--out", help="Run folder (rerun the same command to resume)."),
    action_space: str = typer.Option("macro", "--action-space",
                                     help="macro (6 macro actions) or paper (pysc2 function + "
                                          "screen point)."),
    reward: str = typer.Option("sparse", "--reward", help="sparse, rules, narration or zero (a "
                                                          "control: no reward)."),
    narration: Optional[Path] = typer.Option(
        None, "--narration", help="Narration file (TOML or one command per line) [default: the "
                                  "shipped BuildMarines narration]."),
    mem: Optional[Path] = typer.Option(None, "--mem", help="Trained MEM run (sc2data train "
                                                            "--out), for --reward narration."),
    steps: int = typer.Option(10_000, "--steps", help="Decisions to train for, over all envs."),
    envs: int = typer.Option(16, "--envs", help="Games stepped together (one batched policy "
                                               "and reward call per step)."),
    processes: Optional[int] = typer.Option(
        None, "--processes", help="Worker processes stepping the games (0: in this process) "
                                  "[default: one per core; none for one env]."),
    seed: int = typer.Option(0, "--seed", help="Seed of the policy and the environments."),
    bonus: Optional[float] = typer.Option(
        None, "--bonus", help="Shaping bonus: per rule firing (rules) or per matched "
                              "command (narration) [default: 0.1 rules, 1.0 narration]."),
    threshold: float = typer.Option(0.5, "--threshold",
                                    help="MEM distance below which a command is matched."),
    patience: int = typer.Option(0, "--patience", help="Skip a narration command not matched "
                                                       "within this many decisions (0: never)."),
    shaping: str = typer.Option("event", "--shaping",
                                help="How rules/narration pay their bonus: event (each firing "
                                     "or match) or potential (gamma*phi(s') - phi(s): cannot be "
                                     "farmed)."),
    episode_steps: Optional[int] = typer.Option(
        None, "--episode-steps", help="pysc2 steps per episode on the simulator "
                                      "[default: 1800]."),
    rollout: int = typer.Option(64, "--rollout", help="PPO rollout length per env."),
    batch_size: int = typer.Option(256, "--batch-size", help="PPO minibatch size."),
    checkpoint_every: int = typer.Option(2048, "--checkpoint-every",
                                         help="Decisions between checkpoints."),
    obs: str = typer.Option("compact", "--obs", help="What the policy sees: compact (one-hot "
                                                     "unit types, few layers) or stored (the "
                                                     "stored schema's layers)."),
    obs_size: int = typer.Option(32, "--obs-size", help="compact: 64 or 32 pixels a side."),
    minimap: bool = typer.Option(False, "--minimap/--no-minimap",
                                 help="compact: add the minimap's channels."),
    threads: Optional[int] = typer.Option(
        None, "--threads", help="Torch threads of the learner (policy, MEM, updates) [default: "
                                "one per core]."),
    policy: str = typer.Option("auto", "--policy", help="spatial (paper space: the point given "
                                                        "the function), independent (SB3's "
                                                        "heads) or auto."),
    gamma: float = typer.Option(0.99, "--gamma", help="PPO discount (per pysc2 step with "
                                                      "--smdp)."),
    gae_lambda: float = typer.Option(0.95, "--gae-lambda", help="GAE lambda."),
    epochs: int = typer.Option(4, "--epochs", help="PPO epochs over each rollout."),
    ent_coef: float = typer.Option(0.01, "--ent-coef", help="Entropy bonus coefficient."),
    target_kl: Optional[float] = typer.Option(
        0.05, "--target-kl", help="Stop an update's epochs once the policy moved this far "
                                  "(0: never)."),
    normalize_advantage: bool = typer.Option(
        False, "--normalize-advantage/--raw-advantage",
        help="Normalise advantages per minibatch (SB3's default; off: a zero-reward control "
             "then stays where it started)."),
    smdp: bool = typer.Option(True, "--smdp/--no-smdp",
                              help="Discount a decision of k pysc2 steps by gamma^k."),
    tensorboard: bool = typer.Option(False, "--tensorboard",
                                     help="Also write SB3's log as TensorBoard events "
                                          "(RUN/logs/<session>/; needs tensorboard)."),
    device: str = typer.Option("auto", "--device", help="Policy and MEM on cpu, cuda or auto "
                                                        "(cuda where a GPU is present)."),
    progress: Optional[bool] = typer.Option(None, "--progress/--no-progress",
                                            help="Progress bar [default: on a terminal]."),
) -> None:
    """Train a MaskablePPO agent; writes checkpoints and the learning curve (curve.csv/json)."""
    import time

    from sc2data.rl.train import RLConfig, require_rl, summary_line, train

    require_rl("sc2data rl train")
    cfg = RLConfig(out=str(out), action_space=action_space, reward=reward,
                   narration=None if narration is None else str(narration),
                   mem=None if mem is None else str(mem), steps=steps, envs=envs, seed=seed,
                   bonus=bonus, threshold=threshold, patience=patience, shaping=shaping,
                   episode_steps=episode_steps, rollout=rollout, batch_size=batch_size,
                   checkpoint_every=checkpoint_every, obs=obs, obs_size=obs_size,
                   minimap=minimap, processes=processes, device=device, threads=threads,
                   tensorboard=tensorboard, policy=policy, gamma=gamma, gae_lambda=gae_lambda,
                   epochs=epochs, ent_coef=ent_coef, target_kl=target_kl or None,
                   normalize_advantage=normalize_advantage, smdp=smdp,
                   progress=progress)
    start = time.perf_counter()
    run = train(cfg)
    typer.echo(summary_line(run, time.perf_counter() - start))


@app.command("evaluate")
def evaluate_cmd(
    run: Path = typer.Argument(..., help="Run folder of sc2data rl train."),
    episodes: int = typer.Option(10, "--episodes", help="Seeded episodes never used in training, "
                                                        "half with each start side."),
    progress: Optional[bool] = typer.Option(None, "--progress/--no-progress",
                                            help="Progress bar [default: on a terminal]."),
) -> None:
    """Marines per episode (the game's score), actions sampled and argmax on the same seeded
    episodes; writes RUN/eval.json."""
    from sc2data.rl.evaluate import evaluate, summary
    from sc2data.rl.train import require_rl

    require_rl("sc2data rl evaluate")
    typer.echo(summary(evaluate(run, episodes, progress)))


@app.command("baselines")
def baselines_cmd(
    out: Path = typer.Option(..., "--out", help="Folder for baselines.json."),
    episodes: int = typer.Option(10, "--episodes", help="The evaluation episodes to play (the "
                                                        "same seeds as rl evaluate)."),
    episode_steps: Optional[int] = typer.Option(
        None, "--episode-steps", help="pysc2 steps per episode, as the runs were trained "
                                      "[default: 1800]."),
    progress: Optional[bool] = typer.Option(None, "--progress/--no-progress",
                                            help="Progress bar [default: on a terminal]."),
) -> None:
    """Reference agents on the evaluation episodes: the masked uniform policy of each action
    space, the reduced-random and the scripted agents; writes OUT/baselines.json."""
    from sc2data.rl.evaluate import baselines, reference_summary
    from sc2data.rl.train import require_rl

    require_rl("sc2data rl baselines")
    for line in reference_summary(baselines(out, episodes, episode_steps, progress=progress)):
        typer.echo(line)
    typer.echo(f"wrote {out / 'baselines.json'}")


@app.command("plot")
def plot_cmd(
    runs: list[Path] = typer.Argument(..., help="Run folders to draw in one figure."),
    out: Path = typer.Option(..., "--out", help="PNG file to write."),
    window: int = typer.Option(10, "--window", help="Episodes per rolling mean."),
    group: bool = typer.Option(False, "--group", help="One line per action space, reward and "
                               "narration: the mean over its runs (seeds), shaded min to max."),
    baselines: Optional[Path] = typer.Option(
        None, "--baselines", help="Folder of sc2data rl baselines: reference agents as lines."),
) -> None:
    """Learning curves (marines per episode against pysc2 steps) of several runs in one PNG."""
    from sc2data.rl.evaluate import plot

    typer.echo(f"wrote {plot(runs, out, window, group, baselines, say=typer.echo)}")


@app.command("compare")
def compare_cmd(
    runs: list[Path] = typer.Argument(..., help="Run folders (evaluated: sc2data rl evaluate)."),
    out: Optional[Path] = typer.Option(None, "--out", help="Folder for compare.json and "
                                                           "compare.png [default: print only]."),
    baselines: Optional[Path] = typer.Option(
        None, "--baselines", help="Folder of sc2data rl baselines: reference agents beside."),
    against: Optional[str] = typer.Option(
        None, "--against", help="Probability of improvement of every group over this one "
                                "[default: every pair]."),
    reps: int = typer.Option(2000, "--reps", help="Bootstrap resamples."),
    points: int = typer.Option(20, "--points", help="Points of the sample-efficiency curves."),
    window: int = typer.Option(10, "--window", help="Training episodes per curve point."),
) -> None:
    """Per group of runs (action space, reward, narration; seeds pooled): IQM of the final
    scores with 95 % stratified-bootstrap CIs, probability of improvement between groups and
    sample-efficiency curves (rliable)."""
    from sc2data.rl.compare import compare, summary

    for line in summary(compare(runs, out, baselines=baselines, against=against, reps=reps,
                                points=points, window=window)):
        typer.echo(line)
    if out is not None:
        typer.echo(f"wrote {out / 'compare.json'} and {out / 'compare.png'}")


@app.command("agreement")
def agreement_cmd(
    run: Path = typer.Argument(..., help="Run folder of sc2data rl train (the policy)."),
    mem: Path = typer.Option(..., "--mem", help="Trained MEM run (sc2data train --out)."),
    episodes: int = typer.Option(3, "--episodes", help="Seeded episodes to play."),
    deterministic: bool = typer.Option(False, "--deterministic",
                                       help="Play the most likely action instead of sampling."),
    threshold: Optional[float] = typer.Option(
        None, "--threshold", help="MEM match threshold [default: the model's, 0.5]."),
    out: Optional[Path] = typer.Option(None, "--out",
                                       help="JSON file [default: RUN/agreement.json]."),
) -> None:
    """On the states a trained policy visits: per command, how often the MEM's match agrees
    with the labelling rule (precision, recall and F1, the rule as ground truth); and the
    narration and rules rewards' Pearson correlation and EPIC distance."""
    from sc2data.rl.agreement import agreement, summary
    from sc2data.rl.train import require_rl

    require_rl("sc2data rl agreement")
    for line in summary(agreement(run, mem, episodes=episodes, deterministic=deterministic,
                                  threshold=threshold, out=out)):
        typer.echo(line)


@app.command("fork")
def fork_cmd(
    run: Path = typer.Argument(..., help="Run folder of sc2data rl train --reward narration."),
    out: Path = typer.Option(..., "--out", help="New run folder."),
    mem: Path = typer.Option(..., "--mem", help="The MEM the fork trains on with (sc2data train "
                                                "--out)."),
) -> None:
    """Copy a narration run (checkpoint, trained steps, curve) to train on with another MEM:
    then `sc2data rl train --out OUT --mem MEM` with the run's other options and a larger
    --steps resumes it."""
    from sc2data.rl.fork import fork
    from sc2data.rl.train import require_rl

    require_rl("sc2data rl fork")
    fork(run, out, mem)
    typer.echo(f"forked {run} into {out} with the MEM {mem}")
