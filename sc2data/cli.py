"""The ``sc2data`` command line: a thin layer that parses options and calls the library."""

from __future__ import annotations

import sys

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
