"""The ``sc2data`` command line: a thin layer that parses options and calls the library."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import typer

from sc2data.errors import Sc2DataError

app = typer.Typer(
    name="sc2data",
    help="Natural-language commands grounded in StarCraft II BuildMarines game states.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


@app.callback()
def _root() -> None:
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

_RULES_DIR_HELP = "Also load the rules defined by the .py files of this folder."


@rules_app.command("list")
def rules_list(
    rules_dir: Optional[Path] = typer.Option(None, "--rules-dir", help=_RULES_DIR_HELP),
) -> None:
    """List every rule found, validated: id, version, command text and where it comes from."""
    from sc2data.registry import format_rules, load_registry

    typer.echo(format_rules(load_registry(rules_dir)))


@app.command()
def label(
    data: Path = typer.Argument(..., help="Dataset folder (from sc2data rollout)."),
    rules: Optional[str] = typer.Option(None, "--rules", help="Comma-separated rule ids to use "
                                        "(default: all)."),
    exclude: Optional[str] = typer.Option(None, "--exclude", help="Comma-separated rule ids to "
                                          "leave out."),
    rules_dir: Optional[Path] = typer.Option(None, "--rules-dir", help=_RULES_DIR_HELP),
    batch_size: int = typer.Option(256, "--batch-size", help="Stacks per rule call."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar."),
) -> None:
    """Label every stack of DATA with the rules; writes labels.parquet and stack_labels.parquet."""
    from sc2data.label import label_dataset
    from sc2data.registry import parse_ids

    summary = label_dataset(data, include=parse_ids(rules), exclude=parse_ids(exclude) or [],
                            rules_dir=rules_dir, batch_size=batch_size, progress=progress)
    if summary.up_to_date:
        typer.echo("labels are up to date (same rules, same data)")
    typer.echo(summary.table())


@app.command()
def render(
    out: str = typer.Option(..., "--out", help="PNG file to write."),
    env: str = typer.Option("sim", "--env", help="Backend: sim (embedded) or sc2 (real game)."),
    seed: int = typer.Option(0, "--seed", help="Seed for the environment and the agent."),
    steps: int = typer.Option(300, "--steps", help="Agent steps to play before the frame."),
    agent: str = typer.Option("scripted", "--agent", help="Agent: random, reduced-random, scripted."),
) -> None:
    """Play N steps and draw that frame's 27 screen and 11 minimap layers, coloured as pysc2 does."""
    from sc2data.render import render_episode

    path = render_episode(out, env=env, seed=seed, steps=steps, agent=agent)
    typer.echo(f"wrote {path}")


def main(argv: list[str] | None = None) -> None:
    """Console entry point: user errors become one line on stderr and exit status 2."""
    command = typer.main.get_command(app)
    try:
        command.main(args=argv, prog_name="sc2data", standalone_mode=False)
    except typer.Exit as e:
        sys.exit(e.exit_code)
    except typer.Abort:
        typer.echo("sc2data: interrupted; rerun the same command to resume", err=True)
        sys.exit(130)
    except typer.TyperException as e:  # usage errors: unknown option, bad value, …
        if type(e).__name__ == "NoArgsIsHelpError":  # bare `sc2data`: show the help
            typer.echo(e.ctx.get_help())  # type: ignore[attr-defined]
            sys.exit(0)
        typer.echo(f"sc2data: error: {e.format_message()}", err=True)  # type: ignore[attr-defined]
        sys.exit(getattr(e, "exit_code", 2))
    except Sc2DataError as e:
        typer.echo(f"sc2data: error: {e}", err=True)
        sys.exit(2)
    except KeyboardInterrupt:
        typer.echo("sc2data: interrupted; rerun the same command to resume", err=True)
        sys.exit(130)
