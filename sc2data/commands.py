"""The ``sc2data`` commands: a thin layer that parses options and calls the library.

:mod:`sc2data.cli` is the entry point that runs them (one-line errors, Ctrl-C); this module is
imported only once it has taken over SIGINT, since importing it takes seconds.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Optional

if TYPE_CHECKING:
    from sc2data.scaleout.driver import RayOptions

import typer

from sc2data.cliopts import OptionGroup, config_options, option, with_options
from sc2data.errors import Sc2DataError
from sc2data.model.train import TrainConfig
from sc2data.rl.cli import app as rl_app

app = typer.Typer(
    name="sc2data",
    help="Natural-language commands grounded in StarCraft II BuildMarines game states.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _print_version(value: bool) -> None:
    if value:
        from importlib.metadata import version as package_version

        typer.echo(f"sc2data {package_version('sc2data')}")
        raise typer.Exit()


@app.callback()
def _root(show_version: bool = typer.Option(False, "--version", is_eager=True,
                                            callback=_print_version,
                                            help="Print sc2data's version and exit.")) -> None:
    """Natural-language commands grounded in StarCraft II BuildMarines game states."""


@app.command()
def version() -> None:
    """Print the versions of sc2data and the packages its data records."""
    from sc2data.provenance import versions

    for name, v in versions().items():
        typer.echo(f"{name} {v}")


rules_app = typer.Typer(help="Labelling rules: built-in, from plugins and from --rules-dir.",
                        no_args_is_help=True, rich_markup_mode=None)
app.add_typer(rules_app, name="rules")
app.add_typer(rl_app, name="rl")

_RULES_DIR_HELP = "Also load the rules defined by the .py files of this folder."


# -- option groups shared by several commands --------------------------------------------------
@dataclass(frozen=True)
class RayArgs:
    """The ``--ray*`` options as given; :meth:`options` checks them once the worker count is known."""

    address: str | None
    retries: int
    timeout: float
    memory: int | None

    def options(self, workers: int | None = None) -> RayOptions | None:
        """The scale-out settings (None without ``--ray``); a missing Ray is a one-line error."""
        if self.address is None:
            return None
        from sc2data.scaleout.driver import RayOptions, require_ray

        require_ray()
        options = RayOptions.parse(self.address, retries=self.retries, timeout_s=self.timeout,
                                   memory_mb=self.memory, workers=workers)
        options.validate()
        return options


RAY = OptionGroup("ray", (
    option("ray_address", Optional[str], typer.Option(
        None, "--ray", metavar="[ADDRESS]",
        help="Run as Ray tasks: --ray alone starts a local Ray instance; auto, HOST:PORT or "
             "ray://HOST:PORT joins a running cluster.")),
    option("ray_retries", int, typer.Option(
        2, "--ray-retries",
        help="With --ray: extra attempts per task after a worker death, a crashed game or a hang.")),
    option("ray_timeout", float, typer.Option(
        600.0, "--ray-timeout",
        help="With --ray: seconds a task may go without progress before it is retried.")),
    option("ray_memory", Optional[int], typer.Option(
        None, "--ray-memory",
        help="With --ray: MB of memory to request per task [default: 512 sim, 2048 sc2, 1024 "
             "label].")),
), lambda v: RayArgs(v["ray_address"], v["ray_retries"], v["ray_timeout"], v["ray_memory"]))
"""``--ray`` and its settings (sc2data.scaleout.driver), for rollout, label and build."""

PROGRESS = OptionGroup("progress", (
    option("progress", Optional[bool], typer.Option(
        None, "--progress/--no-progress",
        help="Progress bars [default: on a terminal; with stderr in a file, a line a minute].")),
), lambda v: v["progress"])


@rules_app.command("list")
def rules_list(
    rules_dir: Optional[Path] = typer.Option(None, "--rules-dir", help=_RULES_DIR_HELP),
) -> None:
    """List every rule found, validated: id, version, command text and where it comes from."""
    from sc2data.labels.registry import format_rules, load_registry

    typer.echo(format_rules(load_registry(rules_dir)))


@app.command()
@with_options(PROGRESS, RAY)
def label(
    data: Path = typer.Argument(..., help="Dataset folder (from sc2data rollout)."),
    rules: Optional[str] = typer.Option(None, "--rules", help="Comma-separated rule ids to use "
                                        "(default: all)."),
    exclude: Optional[str] = typer.Option(None, "--exclude", help="Comma-separated rule ids to "
                                          "leave out."),
    rules_dir: Optional[Path] = typer.Option(None, "--rules-dir", help=_RULES_DIR_HELP),
    batch_size: int = typer.Option(256, "--batch-size", help="Stacks per rule call."),
    overwrite: bool = typer.Option(False, help="Replace labels made with another set of rules."),
    workers: int = typer.Option(1, "--workers", help="Processes labelling shards at once "
                                                     "(the labels do not depend on it)."),
    progress: Optional[bool] = None,
    ray: Optional[RayArgs] = None,
) -> None:
    """Label every stack of DATA with the rules; writes labels.parquet and stack_labels.parquet."""
    from sc2data.labels.label import label_dataset
    from sc2data.labels.registry import parse_ids

    selection = {"include": parse_ids(rules), "exclude": parse_ids(exclude) or [],
                 "rules_dir": rules_dir, "batch_size": batch_size, "progress": progress,
                 "overwrite": overwrite}
    lines: list[str] = []
    options = ray.options() if ray else None
    if options is not None:
        from sc2data.scaleout.driver import label_on_ray

        summary, report = label_on_ray(data, options, **selection)
        lines = report.lines() if report.tasks else []
    else:
        summary = label_dataset(data, workers=workers, **selection)
    if summary.up_to_date:
        typer.echo("labels are up to date (same rules, same data)")
    typer.echo(summary.table())
    for line in lines:
        typer.echo(line)


@app.command()
def render(
    data: Optional[Path] = typer.Argument(None, help="Dataset folder (sc2data rollout --out, or a "
                                          "build's OUT/rollout) to draw stored stacks of; "
                                          "without it, a live frame."),
    episode: Optional[int] = typer.Option(None, "--episode", help="With DATA: the stack's "
                                          "episode."),
    step: Optional[int] = typer.Option(None, "--step", help="With DATA: the stack's step in that "
                                       "episode (frames STEP and STEP+1)."),
    rule: Optional[str] = typer.Option(None, "--rule", help="With DATA: draw stacks this rule "
                                       "fired on (needs sc2data label DATA)."),
    limit: Optional[int] = typer.Option(None, "--limit", help="With --rule: how many stacks, "
                                        "spread evenly over those it fired on [default: 8]."),
    out: Optional[str] = typer.Option(None, "--out", help="PNG file to write; with --rule, a "
                                      "folder for the PNGs [default with DATA: "
                                      "./<DATA name>-e<E>-s<S>.png or ./<DATA name>-<RULE>/]."),
    env: Optional[str] = typer.Option(None, "--env", help="Live: sim (embedded, default) or sc2 "
                                      "(real game)."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Live: seed for the environment and "
                                       "the agent [default: 0]."),
    steps: Optional[int] = typer.Option(None, "--steps", help="Live: agent steps to play before "
                                        "the frame [default: 300]."),
    agent: Optional[str] = typer.Option(None, "--agent", help="Live: random, reduced-random or "
                                        "scripted (default)."),
) -> None:
    """Draw feature layers as PNGs, coloured as pysc2 does, each categorical layer's ids in a
    legend with pysc2's names and an all-zero layer marked "empty".

    Live (no DATA): play --steps steps and draw that frame's 27 screen and 11 minimap layers to
    --out.

    DATA --episode E --step S: draw that stored stack, every stored layer, the previous frame
    above the current one, with both frames' minerals, supply, workers, army and score.

    DATA --rule RULE: one PNG per stack, for --limit of the stacks the rule fired on (spread
    evenly over all of them, in episode and step order), into the folder --out as
    e<E>-s<S>.png; page through them to see what the rule takes for its command.
    """
    live = {"env": env, "seed": seed, "steps": steps, "agent": agent}
    stored = {"episode": episode, "step": step, "rule": rule, "limit": limit}
    wrong = [k for k, v in (stored if data is None else live).items() if v is not None]
    if wrong:
        raise Sc2DataError(f"--{wrong[0]} draws stored stacks: give the dataset folder DATA"
                           if data is None else
                           f"--{wrong[0]} is for a live render (no DATA); leave it out")
    if data is None:
        if out is None:
            raise Sc2DataError("a live render needs --out PNG")
        from sc2data.game.render import render_episode

        paths = [render_episode(out, **{k: v for k, v in live.items() if v is not None})]
    elif rule is not None:
        if episode is not None or step is not None:
            raise Sc2DataError("--rule draws the stacks a rule fired on; leave out --episode "
                               "and --step")
        from sc2data.labels.view import DEFAULT_LIMIT, render_rule

        paths = render_rule(data, rule, out or f"{data.name}-{rule}",
                            DEFAULT_LIMIT if limit is None else limit)
    elif episode is None or step is None or limit is not None:
        raise Sc2DataError("with DATA, give --episode E --step S, or --rule RULE [--limit N]")
    else:
        from sc2data.labels.view import render_stored

        paths = [render_stored(data, episode, step,
                               out or f"{data.name}-e{episode}-s{step}.png")]
    for path in paths:
        typer.echo(f"wrote {path}")


@app.command()
@with_options(PROGRESS, RAY)
def rollout(
    out: Path = typer.Option(..., "--out", help="Dataset folder (created; rerun to resume, or "
                                                "with more --episodes to grow it)."),
    env: Optional[str] = typer.Option(None, help="Backend: sim (embedded simulator, default) or "
                                                 "sc2 (the real game)."),
    agent: Optional[str] = typer.Option(None, help="Agent: reduced-random (default), random or "
                                                   "scripted."),
    episodes: Optional[int] = typer.Option(None, help="Episodes to play [default: 1]."),
    seed: Optional[int] = typer.Option(None, help="Root seed; episode e is seeded from (seed, e) "
                                                  "[default: 0]."),
    layers: Optional[str] = typer.Option(None, help="Layer set: paper (13+7, default) or full "
                                                    "(27+11)."),
    recipe: Optional[Path] = typer.Option(None, help="Take the settings above from a recipe "
                                                     "(manifests/*.toml)."),
    workers: Optional[int] = typer.Option(None, help="Worker processes [default: 1]; with --ray, "
                                                     "tasks at once [default: all CPUs]. The "
                                                     "data does not depend on it."),
    episodes_per_shard: Optional[int] = typer.Option(None, help="Episodes per shard file "
                                                                "[default: 8]."),
    max_steps: Optional[int] = typer.Option(None, help="Cut episodes after this many steps."),
    progress: Optional[bool] = None,
    ray: Optional[RayArgs] = None,
) -> None:
    """Play episodes and store every 2-frame stack in sharded, checksummed HDF5.

    Into a dataset folder, the settings not given are the folder's: `--out DATA --episodes N`
    grows DATA to N episodes (or finishes an interrupted run)."""
    from dataclasses import replace

    from sc2data.data.rollout import RolloutConfig, folder_config
    from sc2data.data.rollout import rollout as run
    from sc2data.errors import Sc2DataError

    given = {k: v for k, v in {"env": env, "agent": agent, "episodes": episodes, "seed": seed,
                               "layers": layers}.items() if v is not None}
    extra = {k: v for k, v in {"episodes_per_shard": episodes_per_shard,
                               "max_steps": max_steps}.items() if v is not None}
    if recipe is not None:
        from sc2data.recipe import load

        if given:
            raise Sc2DataError(f"--{next(iter(given))} conflicts with --recipe; change the "
                               f"recipe instead")
        config = RolloutConfig.from_recipe(load(recipe), **extra)
    else:
        base = folder_config(out)
        config = replace(base, **given, **extra) if base else RolloutConfig(**given, **extra)
    lines: list[str] = []
    options = ray.options(workers) if ray else None
    if options is not None:
        from sc2data.scaleout.driver import rollout_on_ray

        s, report = rollout_on_ray(config, out, options, progress=progress)
        lines = report.lines() if report.tasks else []
    else:
        s = run(config, out, workers=1 if workers is None else workers, progress=progress)
    grew = f", grown from {s.grew_from}" if s.grew_from is not None else ""
    typer.echo(f"{s.out}: {s.episodes} episodes{grew}, {s.steps:,} stacks in {s.seconds:.1f} s "
               f"({s.shards_written} shards written, {s.shards_kept} kept)")
    for line in lines:
        typer.echo(line)


@app.command()
@with_options(PROGRESS)
def pair(
    recipe: Path = typer.Argument(..., help="Recipe (manifests/*.toml)."),
    data: Path = typer.Option(..., "--data", help="Labelled dataset folder (sc2data rollout, "
                                                  "then sc2data label)."),
    out: Optional[Path] = typer.Option(None, "--out", help="Pair-set folder [default: "
                                                           "DATA/pairs-<recipe name>]."),
    progress: Optional[bool] = None,
) -> None:
    """Draw the recipe's matched, mismatched and null pairs; pack the stacks of each split."""
    from sc2data.pairs.pairset import make_pairset
    from sc2data.recipe import load

    r = load(recipe)
    s = make_pairset(r, data, out or data / f"pairs-{r.name}", progress=progress)
    typer.echo(("pair set is up to date (same recipe, same labels): " if s.up_to_date else
                f"pair set written in {s.seconds:.1f} s: ") + str(s.out))
    typer.echo(s.table())


@app.command()
@with_options(PROGRESS, RAY)
def build(
    recipe: Path = typer.Argument(..., help="Recipe (manifests/*.toml)."),
    out: Path = typer.Option(..., "--out", help="Build folder (created; rerun to resume)."),
    workers: Optional[int] = typer.Option(None, help="Rollout and label processes [default: 2]; "
                                                     "with --ray, tasks at once [default: all "
                                                     "CPUs]. The data does not depend on it."),
    rules_dir: Optional[Path] = typer.Option(None, "--rules-dir", help=_RULES_DIR_HELP),
    progress: Optional[bool] = None,
    ray: Optional[RayArgs] = None,
) -> None:
    """Run a recipe end to end: rollout → label → pair, resuming whatever is already done."""
    from sc2data.build import PAIRS_DIR
    from sc2data.build import build as run
    from sc2data.recipe import load

    r = load(recipe)
    options = ray.options(workers) if ray else None
    report = run(r, out, workers=2 if workers is None else workers, progress=progress,
                 ray=options, rules_dir=rules_dir)
    for line in report.lines:
        typer.echo(line)
    typer.echo(report.table())
    typer.echo(f"train with: sc2data train {out / PAIRS_DIR} --out RUN")


@app.command()
def info(folder: Path = typer.Argument(..., help="A dataset, pair-set or run folder.")) -> None:
    """What a folder holds: a dataset (episodes, bytes, schema, shards, marines, labels per rule),
    a pair set (pairs per split and kind, commands) or a training run (settings, curves, eval)."""
    from sc2data.folders import info as report

    for line in report(folder):
        typer.echo(line)


@app.command()
def verify(folder: Path = typer.Argument(..., help="A dataset, pair-set or run folder.")) -> None:
    """Check every checksum and record of a dataset (and its labels), a pair set or a training
    run; exit 1 on any fault."""
    from sc2data.folders import verify_folder

    kind, faults, notes = verify_folder(folder)
    for fault in faults:
        typer.echo(f"FAULT {fault}", err=True)
    if faults:
        typer.echo(f"sc2data: {folder}: {len(faults)} fault(s)", err=True)
        raise typer.Exit(1)
    typer.echo(f"{folder}: OK ({kind}{'; ' + '; '.join(notes) if notes else ''})")


@app.command("train")
@with_options(config_options(TrainConfig, arguments={
    "data": "Pair-set folder (sc2data pair / build output)."}, flags={"progress": "--progress/--no-progress"}))
def train_cmd(config: Optional[TrainConfig] = None) -> None:
    """Train the mutual-embedding model; keep the checkpoint of minimum validation loss."""
    from sc2data.model.train import train

    assert config is not None
    typer.echo(f"run: {train(config)}")


@app.command("evaluate")
@with_options(PROGRESS)
def evaluate_cmd(
    run: Path = typer.Argument(..., help="Run folder (sc2data train --out)."),
    data: Optional[Path] = typer.Option(None, help="Pair-set folder [default: the run's]."),
    device: str = typer.Option("auto", help="auto, cpu or cuda."),
    text: list[str] = typer.Option([], "--text", help="A phrasing to measure, as "
                                   "\"PHRASE=command_id\" (repeatable)."),
    allow_unfinished: bool = typer.Option(False, help="Evaluate a run that did not finish."),
    other_data: bool = typer.Option(False, help="Evaluate on a pair set other than the run's own "
                                                "(report: RUN/eval-<fingerprint>.json)."),
    progress: Optional[bool] = None,
) -> None:
    """Accuracy (beside the paper's), ROC-AUC, retrieval, phrasings; writes RUN/eval.json."""
    from sc2data.model.evaluate import evaluate, format_report

    report = evaluate(run, data, device, text, allow_unfinished, other_data, progress)
    typer.echo(format_report(report))
    typer.echo(f"wrote {report['written_to']}")


@app.command("tsne")
@with_options(PROGRESS)
def tsne_cmd(
    run: Path = typer.Argument(..., help="Run folder (sc2data train --out)."),
    data: Optional[Path] = typer.Option(None, help="Pair-set folder [default: the run's]."),
    out: Optional[Path] = typer.Option(None, help="PNG path [default: RUN/tsne.png]."),
    states: int = typer.Option(2000, min=1, help="Test states to plot (a random sample)."),
    text: list[str] = typer.Option([], "--text", help="Extra command text to mark, "
                                   "\"PHRASE\" or \"PHRASE=command_id\" (repeatable)."),
    seed: int = typer.Option(0, help="Seed of the sample and of t-SNE."),
    device: str = typer.Option("auto", help="auto, cpu or cuda."),
    allow_unfinished: bool = typer.Option(False, help="Draw a run that did not finish."),
    progress: Optional[bool] = None,
) -> None:
    """A t-SNE map of state and command embeddings, like the paper's Fig. 3."""
    from sc2data.model.evaluate import tsne

    path = tsne(run, data, out, states, seed, text, device, allow_unfinished, progress)
    typer.echo(f"wrote {path}")
