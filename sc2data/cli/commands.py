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

from dataclasses import replace

import typer
from typer.core import TyperGroup

from sc2data.cli.cliopts import OptionGroup, config_options, option, plural, with_options
from sc2data.cli.rl import app as rl_app
from sc2data.ground.errors import Sc2DataError
from sc2data.model.train import TrainConfig, train

PIPELINE = ("rollout", "label", "pair", "build", "train", "evaluate", "tsne", "rl", "export",
            "info", "verify", "render", "rules", "version")
"""The commands in the order ``sc2data --help`` lists them: the pipeline's, then the tools."""


class _PipelineOrder(TyperGroup):
    """Lists the commands in :data:`PIPELINE` order, not alphabetically nor as defined."""

    def list_commands(self, ctx: typer.Context) -> list[str]:  # type: ignore[override]
        names = super().list_commands(ctx)
        return sorted(names, key=lambda n: PIPELINE.index(n) if n in PIPELINE else len(PIPELINE))


app = typer.Typer(
    name="sc2data",
    cls=_PipelineOrder,
    help="Natural-language commands grounded in StarCraft II BuildMarines game states.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)

_MORE_VERSIONS = ("torch", "stable-baselines3", "sb3-contrib", "gymnasium", "minari", "datasets")
"""Packages whose versions ``sc2data version`` adds to those the data records."""


def version_lines() -> list[str]:
    """sc2data's version, then those of the packages its data records and of the optional ones
    that train and export it ("not installed" where absent); reads package metadata only."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as package_version

    from sc2data.ground.provenance import versions

    found = dict(versions())
    for dist in _MORE_VERSIONS:
        try:
            found[dist] = package_version(dist)
        except PackageNotFoundError:
            found[dist] = "not installed"
    return [f"{name} {v}" for name, v in found.items()]


def _print_version(value: bool) -> None:
    if value:
        for line in version_lines():
            typer.echo(line)
        raise typer.Exit()


@app.callback()
def _root(show_version: bool = typer.Option(False, "--version", is_eager=True,
                                            callback=_print_version,
                                            help="Print what sc2data version prints and exit.")
          ) -> None:
    """Natural-language commands grounded in StarCraft II BuildMarines game states."""


@app.command()
def version() -> None:
    """The versions of sc2data, of the packages its data records and of the optional ones (torch,
    SB3, gymnasium, Minari, datasets); the same as sc2data --version."""
    for line in version_lines():
        typer.echo(line)


rules_app = typer.Typer(help="Labelling rules: built-in, from plugins and from --rules-dir.",
                        no_args_is_help=True, rich_markup_mode=None)
app.add_typer(rules_app, name="rules")
app.add_typer(rl_app, name="rl")

_RULES_DIR_HELP = "Also load the rules defined by the .py files of this folder."


# -- option groups shared by several commands --------------------------------------------------
@dataclass(frozen=True)
class RayArgs:
    """The ``--ray*`` options as given; :meth:`options` checks them once the worker count is
    known."""

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
        help="With --ray: extra attempts per task after a worker death, a crashed game or a "
             "hang.")),
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
    rules_dir: Optional[Path] = typer.Option(None, "--rules-dir", metavar="DIR",
                                             help=_RULES_DIR_HELP),
) -> None:
    """List every rule found, validated: id, version, command text and where it comes from."""
    from sc2data.labels.registry import format_rules, load_registry

    typer.echo(format_rules(load_registry(rules_dir)))


@app.command()
@with_options(PROGRESS, RAY)
def label(
    data: Path = typer.Argument(..., metavar="DATA", help="Dataset folder (sc2data rollout "
                                                          "--out)."),
    rules: Optional[str] = typer.Option(None, "--rules", metavar="IDS",
                                        help="Comma-separated rule ids to use [default: all]."),
    exclude: Optional[str] = typer.Option(None, "--exclude", metavar="IDS",
                                          help="Comma-separated rule ids to leave out."),
    rules_dir: Optional[Path] = typer.Option(None, "--rules-dir", metavar="DIR",
                                             help=_RULES_DIR_HELP),
    batch_size: int = typer.Option(256, "--batch-size", help="Stacks per rule call."),
    overwrite: bool = typer.Option(False, help="Replace labels made with another set of rules."),
    workers: int = typer.Option(1, "--workers", help="Processes labelling shards at once "
                                                     "(the labels do not depend on it)."),
    progress: Optional[bool] = None,
    ray: Optional[RayArgs] = None,
) -> None:
    """Label every stack of DATA with the rules; writes labels.parquet and stack_labels.parquet."""
    from sc2data.folders import expect_dataset
    from sc2data.labels.registry import parse_ids
    from sc2data.scaleout.where import run_label

    expect_dataset(data)
    selection = {"include": parse_ids(rules), "exclude": parse_ids(exclude) or [],
                 "rules_dir": rules_dir, "batch_size": batch_size, "progress": progress,
                 "overwrite": overwrite}
    summary, lines = run_label(data, workers=workers, ray=ray.options() if ray else None,
                               **selection)
    if summary.up_to_date:
        typer.echo("labels are up to date (same rules, same data)")
    typer.echo(summary.table())
    for line in lines:
        typer.echo(line)


@app.command()
def render(
    data: Optional[Path] = typer.Argument(None, metavar="[DATA]",
                                          help="Dataset folder (sc2data rollout --out, or a "
                                          "build's OUT/rollout) to draw stored stacks of; "
                                          "without it, a live frame."),
    episode: Optional[int] = typer.Option(None, "--episode", help="With DATA: the stack's "
                                          "episode."),
    step: Optional[int] = typer.Option(None, "--step", help="With DATA: the stack's step in that "
                                       "episode (frames STEP and STEP+1)."),
    rule: Optional[str] = typer.Option(None, "--rule", metavar="ID",
                                       help="With DATA: draw stacks this rule fired on (needs "
                                       "sc2data label DATA)."),
    limit: Optional[int] = typer.Option(None, "--limit", help="With --rule: how many stacks, "
                                        "spread evenly over those it fired on [default: 8]."),
    out: Optional[Path] = typer.Option(None, "--out", help="PNG file to write; with --rule, a "
                                       "folder for the PNGs [default: with DATA, "
                                       "./<DATA name>-e<E>-s<S>.png or ./<DATA name>-<RULE>/]."),
    env: Optional[str] = typer.Option(None, "--env", help="Live: sim (the embedded simulator) or "
                                      "sc2 (the real game) [default: sim]."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Live: seed for the environment and "
                                       "the agent [default: 0]."),
    steps: Optional[int] = typer.Option(None, "--steps", help="Live: agent steps to play before "
                                        "the frame [default: 300]."),
    agent: Optional[str] = typer.Option(None, "--agent", help="Live: reduced-random, random, "
                                        "scripted or policy:RUN (a trained sc2data rl run) "
                                        "[default: reduced-random, as sc2data rollout]."),
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
    if data is not None:
        from sc2data.folders import expect_dataset

        expect_dataset(data)
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
        from sc2data.ground.recipe import RolloutSpec

        live["agent"] = agent or RolloutSpec.agent  # one default agent: rollout's
        paths = [render_episode(out, **{k: v for k, v in live.items() if v is not None})]
    elif rule is not None:
        if episode is not None or step is not None:
            raise Sc2DataError("--rule draws the stacks a rule fired on; leave out --episode "
                               "and --step")
        from sc2data.labels.view import DEFAULT_LIMIT, render_rule

        paths = render_rule(data, rule, out or Path(f"{data.name}-{rule}"),
                            DEFAULT_LIMIT if limit is None else limit)
    elif episode is None or step is None or limit is not None:
        raise Sc2DataError("with DATA, give --episode E --step S, or --rule RULE [--limit N]")
    else:
        from sc2data.labels.view import render_stored

        paths = [render_stored(data, episode, step,
                               out or Path(f"{data.name}-e{episode}-s{step}.png"))]
    for path in paths:
        typer.echo(f"wrote {path}")


@app.command()
@with_options(PROGRESS, RAY)
def rollout(
    out: Path = typer.Option(..., "--out", help="Dataset folder (created; rerun to resume, or "
                                                "with more --episodes to grow it)."),
    env: Optional[str] = typer.Option(None, help="Backend: sim (the embedded simulator) or sc2 "
                                                 "(the real game) [default: sim]."),
    agent: Optional[str] = typer.Option(None, help="Agent: reduced-random, random, scripted or "
                                                   "policy:RUN (a trained sc2data rl run's "
                                                   "policy, sampled) [default: reduced-random]."),
    episodes: Optional[int] = typer.Option(None, help="Episodes to play [default: 1]."),
    seed: Optional[int] = typer.Option(None, help="Root seed; episode e is seeded from (seed, e) "
                                                  "[default: 0]."),
    layers: Optional[str] = typer.Option(None, help="Layer set: paper (13+7) or full (27+11) "
                                                    "[default: paper]."),
    recipe: Optional[Path] = typer.Option(None, metavar="RECIPE",
                                          help="Take the settings above from a recipe "
                                               "(manifests/*.toml)."),
    workers: Optional[int] = typer.Option(None, help="Worker processes [default: 1]; with --ray, "
                                                     "tasks at once [default: all CPUs]. The "
                                                     "data does not depend on it."),
    episodes_per_shard: Optional[int] = typer.Option(None, help="Episodes per shard file "
                                                                "[default: 8]."),
    max_steps: Optional[int] = typer.Option(None, help="Cut episodes after this many steps "
                                                       "[default: play them to the end]."),
    progress: Optional[bool] = None,
    ray: Optional[RayArgs] = None,
) -> None:
    """Play episodes and store every 2-frame stack in sharded, checksummed HDF5.

    Into a dataset folder, the settings not given are the folder's: `--out DATA --episodes N`
    grows DATA to N episodes (or finishes an interrupted run)."""
    from sc2data.data.rollout import RolloutConfig, folder_config
    from sc2data.scaleout.where import run_rollout

    given = {k: v for k, v in {"env": env, "agent": agent, "episodes": episodes, "seed": seed,
                               "layers": layers}.items() if v is not None}
    extra = {k: v for k, v in {"episodes_per_shard": episodes_per_shard,
                               "max_steps": max_steps}.items() if v is not None}
    if recipe is not None:
        from sc2data.ground.recipe import load

        if given:
            raise Sc2DataError(f"--{next(iter(given))} conflicts with --recipe; change the "
                               f"recipe instead")
        config = RolloutConfig.from_recipe(load(recipe), **extra)
    else:
        base = folder_config(out)
        config = replace(base, **given, **extra) if base else RolloutConfig(**given, **extra)
    s, lines = run_rollout(config, out, workers=1 if workers is None else workers,
                           progress=progress, ray=ray.options(workers) if ray else None)
    grew = f", grown from {s.grew_from}" if s.grew_from is not None else ""
    typer.echo(f"{s.out}: {plural(s.episodes, 'episode')}{grew}, {plural(s.steps, 'stack')} in "
               f"{s.seconds:.1f} s ({plural(s.shards_written, 'shard')} written, "
               f"{s.shards_kept} kept)")
    for line in lines:
        typer.echo(line)


@app.command()
@with_options(PROGRESS)
def pair(
    recipe: Path = typer.Argument(..., metavar="RECIPE", help="Recipe (manifests/*.toml)."),
    data: Path = typer.Option(..., "--data", metavar="DATA",
                              help="Labelled dataset folder (sc2data rollout, then sc2data "
                                   "label)."),
    out: Optional[Path] = typer.Option(None, "--out", help="Pair-set folder [default: "
                                                           "DATA/pairs-<recipe name>]."),
    progress: Optional[bool] = None,
) -> None:
    """Draw the recipe's matched, mismatched and null pairs; pack the stacks of each split."""
    from sc2data.folders import expect_dataset
    from sc2data.ground.recipe import load
    from sc2data.pairs.pairset import make_pairset

    r = load(recipe)
    # A recipe of several sources reads each from a folder inside --data.
    expect_dataset(data, "--data", builds=bool(getattr(r, "sources", None)))
    s = make_pairset(r, data, out or data / f"pairs-{r.name}", progress=progress)
    typer.echo(("pair set is up to date (same recipe, same labels): " if s.up_to_date else
                f"pair set written in {s.seconds:.1f} s: ") + str(s.out))
    typer.echo(s.table())


@app.command()
@with_options(PROGRESS, RAY)
def build(
    recipe: Path = typer.Argument(..., metavar="RECIPE", help="Recipe (manifests/*.toml)."),
    out: Path = typer.Option(..., "--out", help="Build folder (created; rerun to resume): "
                                                "OUT/rollout the dataset, OUT/pairs the pair "
                                                "set."),
    workers: Optional[int] = typer.Option(None, help="Rollout and label processes [default: 2]; "
                                                     "with --ray, tasks at once [default: all "
                                                     "CPUs]. The data does not depend on it."),
    rules_dir: Optional[Path] = typer.Option(None, "--rules-dir", metavar="DIR",
                                             help=_RULES_DIR_HELP),
    progress: Optional[bool] = None,
    ray: Optional[RayArgs] = None,
) -> None:
    """Run a recipe end to end: rollout → label → pair, resuming whatever is already done."""
    from sc2data.build import PAIRS_DIR
    from sc2data.build import build as run
    from sc2data.ground.recipe import load

    r = load(recipe)
    options = ray.options(workers) if ray else None
    report = run(r, out, workers=2 if workers is None else workers, progress=progress,
                 ray=options, rules_dir=rules_dir)
    for line in report.lines:
        typer.echo(line)
    typer.echo(report.table())
    typer.echo(f"train with: sc2data train {out / PAIRS_DIR} --out RUN")


_FOLDER_HELP = ("A folder sc2data writes: a dataset, pair set, training run, RL run or build "
                "folder.")


@app.command()
def info(folder: Path = typer.Argument(..., metavar="FOLDER", help=_FOLDER_HELP)) -> None:
    """What a folder holds: a dataset (episodes, bytes, schema, shards, marines, labels per rule),
    a pair set (pairs per split and kind, commands), a training run (settings, curves, eval), an
    RL run (settings, progress, curve, eval) or a build (its dataset and pair set)."""
    from sc2data.folders import info as report

    for line in report(folder):
        typer.echo(line)


@app.command()
def verify(folder: Path = typer.Argument(..., metavar="FOLDER", help=_FOLDER_HELP)) -> None:
    """Check every checksum and record of a dataset (and its labels), a pair set, a training run,
    an RL run or a build; exit 1 on any fault."""
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
    "data": ("PAIRS", "Pair-set folder (sc2data pair --out, or a build's OUT/pairs).")},
    flags={"progress": "--progress/--no-progress"},
    metavars={"out": "PATH", "vectors": "PATH", "init": "RUN"}))
def train_cmd(config: Optional[TrainConfig] = None) -> None:
    """Train the mutual-embedding model; keep the checkpoint of minimum validation loss."""
    assert config is not None
    typer.echo(f"run: {train(config)}")


@app.command("evaluate")
@with_options(PROGRESS)
def evaluate_cmd(
    run: Path = typer.Argument(..., metavar="RUN", help="Run folder (sc2data train --out)."),
    data: Optional[Path] = typer.Option(None, metavar="PAIRS",
                                        help="Pair-set folder [default: the run's]."),
    device: str = typer.Option("auto", help="auto, cpu or cuda."),
    text: list[str] = typer.Option([], "--text", metavar="PHRASE=ID",
                                   help="A phrasing to measure, as \"PHRASE=command_id\" "
                                        "(repeatable)."),
    allow_unfinished: bool = typer.Option(False, help="Evaluate a run that did not finish."),
    other_data: bool = typer.Option(False, help="Evaluate on a pair set other than the run's own "
                                                "(report: RUN/eval-<fingerprint>.json)."),
    progress: Optional[bool] = None,
) -> None:
    """Accuracy (beside the paper's), ROC-AUC, retrieval, phrasings; writes RUN/eval.json."""
    from sc2data.model.evaluate import evaluate, format_report

    report = evaluate(run, data, device=device, texts=text, allow_unfinished=allow_unfinished,
                      other_data=other_data, progress=progress)
    typer.echo(format_report(report))
    typer.echo(f"wrote {report['written_to']}")


@app.command("tsne")
@with_options(PROGRESS)
def tsne_cmd(
    run: Path = typer.Argument(..., metavar="RUN", help="Run folder (sc2data train --out)."),
    data: Optional[Path] = typer.Option(None, metavar="PAIRS",
                                        help="Pair-set folder [default: the run's]."),
    out: Optional[Path] = typer.Option(None, help="PNG path [default: RUN/tsne.png]."),
    states: int = typer.Option(2000, min=1, help="Test states to plot (a random sample)."),
    text: list[str] = typer.Option([], "--text", metavar="PHRASE[=ID]",
                                   help="Extra command text to mark, \"PHRASE\" or "
                                        "\"PHRASE=command_id\" (repeatable)."),
    seed: int = typer.Option(0, help="Seed of the sample and of t-SNE."),
    device: str = typer.Option("auto", help="auto, cpu or cuda."),
    allow_unfinished: bool = typer.Option(False, help="Draw a run that did not finish."),
    progress: Optional[bool] = None,
) -> None:
    """A t-SNE map of state and command embeddings, like the paper's Fig. 3."""
    from sc2data.model.evaluate import tsne

    path = tsne(run, data, out=out, states=states, seed=seed, texts=text, device=device,
                allow_unfinished=allow_unfinished, progress=progress)
    typer.echo(f"wrote {path}")


@app.command("export")
@with_options(PROGRESS)
def export_cmd(
    data: Path = typer.Argument(..., metavar="DATA", help="Dataset folder (sc2data rollout "
                                                          "--out)."),
    to: str = typer.Option(..., "--to", metavar="FORMAT",
                           help="npz (numpy files), minari (a Minari dataset) or hf (a Hugging "
                                "Face datasets dataset)."),
    out: Path = typer.Option(..., "--out", help="Folder to write (made whole, or not at all)."),
    name: Optional[str] = typer.Option(None, "--name", help="The dataset's name (Minari id "
                                       "sc2data/NAME-v0) [default: DATA's folder name]."),
    episodes: Optional[int] = typer.Option(None, "--episodes", help="Export the first N "
                                           "episodes [default: all]."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing OUT."),
    progress: Optional[bool] = None,
) -> None:
    """Export the episodes of DATA for other tools: observations (T+1 per episode), the pysc2
    actions, rewards, terminations and truncations; read back by numpy, Minari or datasets."""
    from sc2data.data.export import export
    from sc2data.folders import expect_dataset

    expect_dataset(data)
    s = export(data, to, out, name=name, episodes=episodes, overwrite=overwrite,
               progress=progress)
    typer.echo(f"wrote {s.out} ({s.to}): {plural(s.episodes, 'episode')}, "
               f"{plural(s.steps, 'step')}, {s.bytes:,} bytes in {s.seconds:.1f} s")
    typer.echo(f"read it with: {s.read_with}")
