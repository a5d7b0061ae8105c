"""``sc2data rl …``: train, evaluate, compare and plot narration-guided (or unshaped) agents.

Heavy packages (gymnasium, stable-baselines3, torch) are imported inside the commands, so
``sc2data --help`` stays fast and a missing ``rl`` extra is a one-line error naming it.
``rl train``'s options are :class:`~sc2data.rl.train.RLConfig`'s fields: add an option there.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Optional

import typer

from sc2data.cli.cliopts import config_options, with_options

# sc2data.rl.train imports numpy only: the heavy packages load inside train() and require_rl().
from sc2data.rl.train import RLConfig, require_rl, summary_line, train, trained_steps

app = typer.Typer(help="Reinforcement learning on BuildMarines: sparse, rule-shaped or "
                       "narration-shaped rewards (MaskablePPO).",
                  no_args_is_help=True, rich_markup_mode=None)


@app.command("train")
@with_options(config_options(
    RLConfig, metavars={"out": "PATH", "narration": "PATH", "mem": "PATH"},
    flags={"normalize_advantage": "--normalize-advantage/--raw-advantage",
           "tensorboard": "--tensorboard", "progress": "--progress/--no-progress"}))
def train_cmd(config: Optional[RLConfig] = None) -> None:
    """Train a MaskablePPO agent; writes checkpoints and the learning curve (curve.csv/json)."""
    assert config is not None
    require_rl("sc2data rl train")
    before = trained_steps(Path(config.out))
    start = time.perf_counter()
    run = train(config)
    typer.echo(summary_line(run, time.perf_counter() - start, since=before))


@app.command("evaluate")
def evaluate_cmd(
    run: Path = typer.Argument(..., help="Run folder of sc2data rl train."),
    episodes: int = typer.Option(10, "--episodes", help="Seeded episodes never used in training, "
                                                        "half with each start side."),
    processes: Optional[int] = typer.Option(
        None, "--processes", help="Worker processes the episodes are spread over (the figures "
        "are the same) [default: one per core; 1 with the real game]."),
    progress: Optional[bool] = typer.Option(None, "--progress/--no-progress",
                                            help="Progress bar [default: on a terminal]."),
) -> None:
    """Marines per episode (the game's score), actions sampled and argmax on the same seeded
    episodes; writes RUN/eval.json."""
    from sc2data.rl.evaluate import evaluate, summary

    require_rl("sc2data rl evaluate")
    typer.echo(summary(evaluate(run, episodes, progress, processes)))


@app.command("baselines")
def baselines_cmd(
    out: Path = typer.Option(..., "--out", help="Folder for baselines.json."),
    episodes: int = typer.Option(10, "--episodes", help="The evaluation episodes to play (the "
                                                        "same seeds as rl evaluate)."),
    episode_steps: Optional[int] = typer.Option(
        None, "--episode-steps", help="pysc2 steps per episode, as the runs were trained "
                                      "[default: 1800]."),
    macro_sites: str = typer.Option(
        "random", "--macro-sites", help="Where the macro agents build: random or far, as the "
                                        "runs were trained."),
    progress: Optional[bool] = typer.Option(None, "--progress/--no-progress",
                                            help="Progress bar [default: on a terminal]."),
) -> None:
    """Reference agents on the evaluation episodes: the masked uniform policy of each action
    space, the reduced-random, macro-rules and scripted agents; writes OUT/baselines.json."""
    from sc2data.rl.evaluate import baselines, reference_summary

    require_rl("sc2data rl baselines")
    record = baselines(out, episodes, episode_steps, progress=progress, sites=macro_sites)
    for line in reference_summary(record):
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
    window: int = typer.Option(
        1, "--window", help="Each game's last training episodes per curve point (with 16 "
                            "games, 1 gives 16 episodes a point)."),
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


@app.command("record")
def record_cmd(
    run: Path = typer.Argument(..., help="Run folder of sc2data rl train, evaluated."),
    out: Path = typer.Option(..., "--out", help="Folder for the record (a new one, or a record "
                                                "to replace)."),
) -> None:
    """Keep a finished run without its model: settings, training curve and evaluation (about
    20 kB against a 3.4 MB paper-space model), which rl compare and rl plot read as the run."""
    from sc2data.rl.record import record

    entry = record(run, out)
    typer.echo(f"recorded {run} ({entry['timesteps']:,} decisions, evaluated) into {out}")


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
    progress: Optional[bool] = typer.Option(None, "--progress/--no-progress",
                                            help="Progress bar [default: on a terminal]."),
) -> None:
    """On the states a trained policy visits: per command, how often the MEM's match agrees
    with the labelling rule (precision, recall and F1, the rule as ground truth; recall also
    where the rule was the only one to fire); on the simulator, the rule and the MEM against
    the game's own record; and the narration and rules rewards' Pearson correlation and EPIC
    distance."""
    from sc2data.rl.agreement import agreement, summary

    require_rl("sc2data rl agreement")
    for line in summary(agreement(run, mem, episodes=episodes, deterministic=deterministic,
                                  threshold=threshold, out=out, progress=progress)):
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

    require_rl("sc2data rl fork")
    fork(run, out, mem)
    typer.echo(f"forked {run} into {out} with the MEM {mem}")
