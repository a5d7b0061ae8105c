"""``sc2data rl …``: train, evaluate and plot narration-guided (or unshaped) agents.

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
                                  "[one per core; none for one env]."),
    seed: int = typer.Option(0, "--seed", help="Seed of the policy and the environments."),
    bonus: Optional[float] = typer.Option(
        None, "--bonus", help="Shaping bonus: per rule firing (rules) [0.1] or per matched "
                              "command (narration) [1.0]."),
    threshold: float = typer.Option(0.5, "--threshold",
                                    help="MEM distance below which a command is matched."),
    patience: int = typer.Option(0, "--patience", help="Skip a narration command not matched "
                                                       "within this many decisions (0: never)."),
    episode_steps: Optional[int] = typer.Option(
        None, "--episode-steps", help="pysc2 steps per episode on the simulator [1800]."),
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
        None, "--threads", help="Torch threads of the learner (policy, MEM, updates) [one per "
                                "core]."),
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
                   bonus=bonus, threshold=threshold, patience=patience,
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
    episodes: int = typer.Option(10, "--episodes", help="Seeded episodes never used in training."),
    stochastic: bool = typer.Option(False, "--stochastic",
                                    help="Sample actions instead of the most likely one."),
    progress: Optional[bool] = typer.Option(None, "--progress/--no-progress",
                                            help="Progress bar [default: on a terminal]."),
) -> None:
    """Marines per episode (the game's score), mean ± std; writes RUN/eval.json
    (RUN/eval-stochastic.json with --stochastic)."""
    from sc2data.rl.train import evaluate, require_rl, summary

    require_rl("sc2data rl evaluate")
    typer.echo(summary(evaluate(run, episodes, not stochastic, progress)))


@app.command("plot")
def plot_cmd(
    runs: list[Path] = typer.Argument(..., help="Run folders to draw in one figure."),
    out: Path = typer.Option(..., "--out", help="PNG file to write."),
    window: int = typer.Option(10, "--window", help="Episodes per rolling mean."),
    group: bool = typer.Option(False, "--group", help="One line per action space, reward and "
                               "narration: the mean over its runs (seeds), shaded min to max."),
) -> None:
    """Learning curves (marines per episode against pysc2 steps) of several runs in one PNG."""
    from sc2data.rl.train import plot

    typer.echo(f"wrote {plot(runs, out, window, group)}")


@app.command("agreement")
def agreement_cmd(
    run: Path = typer.Argument(..., help="Run folder of sc2data rl train (the policy)."),
    mem: Path = typer.Option(..., "--mem", help="Trained MEM run (sc2data train --out)."),
    episodes: int = typer.Option(3, "--episodes", help="Seeded episodes to play."),
    deterministic: bool = typer.Option(False, "--deterministic",
                                       help="Play the most likely action instead of sampling."),
    threshold: Optional[float] = typer.Option(None, "--threshold",
                                              help="MEM match threshold [the model's: 0.5]."),
    out: Optional[Path] = typer.Option(None, "--out", help="JSON file [RUN/agreement.json]."),
) -> None:
    """On the states a trained policy visits: per command, how often the MEM's match agrees
    with the labelling rule (precision and recall, the rule as ground truth)."""
    from sc2data.rl.agreement import agreement, summary
    from sc2data.rl.train import require_rl

    require_rl("sc2data rl agreement")
    for line in summary(agreement(run, mem, episodes=episodes, deterministic=deterministic,
                                  threshold=threshold, out=out)):
        typer.echo(line)
