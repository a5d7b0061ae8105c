"""The ``sc2data`` entry point: every way a command ends is an exit status and at most one line.

User errors (:class:`~sc2data.ground.errors.Sc2DataError`, bad options) print
``sc2data: error: …`` and exit 2; Ctrl-C prints ``sc2data: interrupted; …`` and exits 130,
wherever it lands:

* SIGINT is taken over before anything else is imported (the commands, :mod:`sc2data.cli.commands`,
  take seconds to import: pysc2, PyTorch), so a Ctrl-C at start-up is handled like any other;
* the first Ctrl-C raises ``KeyboardInterrupt`` where the command is, so its cleanup runs (workers
  stopped, ``….partial`` files removed); a second one while that runs does not interrupt it
  (cut short, it would leave debris and tracebacks); a third stops the process at once, with
  the same status and line, as a cleanup that hangs would need: every file is then complete
  under its final name or a ``….partial`` one that readers and reruns discard, as after ``kill``;
* once the command's outcome is printed, Ctrl-C is ignored while Python shuts down (whose
  default handler would kill the process with status −2), and CPython's mark of an unhandled
  interrupt, which ``python -m`` would act on the same way, is cleared.

A process started with SIGINT ignored (a background job) keeps ignoring it.
"""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType
from typing import Any

INTERRUPTED = "sc2data: interrupted; rerun the same command to resume"
_said = False


def _say_interrupted(handler: bool = False) -> None:
    """Print the interruption line, once per process (from a signal ``handler``: straight to fd
    2, since the handler may have interrupted a write to ``sys.stderr``)."""
    global _said
    if _said:
        return
    _said = True
    if not handler:
        print(INTERRUPTED, file=sys.stderr, flush=True)
        return
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, RuntimeError, ValueError):  # closed, or re-entered mid-write
            pass
    os.write(2, f"{INTERRUPTED}\n".encode())


def _stop_at_once(signum: int, frame: FrameType | None) -> None:
    """A third Ctrl-C: the cleanup seems stuck; exit 130 now."""
    _say_interrupted(handler=True)
    os._exit(130)


def _cleaning_up(signum: int, frame: FrameType | None) -> None:
    """A second Ctrl-C while the first is handled: let the cleanup finish; a third stops at
    once."""
    signal.signal(signal.SIGINT, _stop_at_once)


def _interrupt(signum: int, frame: FrameType | None) -> None:
    """The first Ctrl-C: interrupt the command where it is."""
    signal.signal(signal.SIGINT, _cleaning_up)
    raise KeyboardInterrupt


def _take_sigint() -> Any:
    """Handle SIGINT from now on, unless it is ignored or this is not the main thread; returns
    the handler it replaced (None: left alone)."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        return None
    try:
        return signal.signal(signal.SIGINT, _interrupt)
    except ValueError:  # not the main thread: its caller handles signals
        return None


def _forget_unhandled_interrupt() -> None:
    """Clear CPython's mark of a ``KeyboardInterrupt`` left unhandled: it is set whenever one
    passes out of ``exec`` or ``eval`` of a string (dataclasses and namedtuples make their methods
    so), even when it is handled further up, and ``python -m`` ends a marked process by SIGINT
    (status -2) after it has exited. Each such ``exec`` clears the mark as it starts."""
    exec("None")  # noqa: S102 - a constant, compiled for its side effect above


def _bare_ray(argv: list[str]) -> list[str]:
    """``--ray`` with no address means ``--ray local``: typer has no optional option values."""
    from sc2data.scaleout.driver import is_address

    out: list[str] = []
    for j, arg in enumerate(argv):
        out.append(arg)
        if arg == "--ray" and (j + 1 == len(argv) or not is_address(argv[j + 1])):
            out.append("local")
    return out


def _run(argv: list[str]) -> int:
    """Run one command line; its exit status, every message printed."""
    import typer

    from sc2data.cli.cliopts import one_voice
    from sc2data.cli.commands import app
    from sc2data.ground.errors import Sc2DataError

    command = one_voice(typer.main.get_command(app))
    try:
        rc = command.main(args=_bare_ray(argv), prog_name="sc2data", standalone_mode=False)
        # Non-standalone click returns typer.Exit(code) instead of raising it; typer turns a
        # Ctrl-C inside a command into a returned 130.
        return rc if isinstance(rc, int) else 0
    except typer.Exit as e:
        return e.exit_code
    except typer.Abort:
        return 130
    except typer.TyperException as e:  # usage errors: unknown option, bad value, …
        if type(e).__name__ == "NoArgsIsHelpError":  # bare `sc2data`: show the help
            typer.echo(e.ctx.get_help())  # type: ignore[attr-defined]
            return 0
        typer.echo(f"sc2data: error: {e.format_message()}", err=True)  # type: ignore[attr-defined]
        return int(getattr(e, "exit_code", 2))
    except Sc2DataError as e:
        typer.echo(f"sc2data: error: {e}", err=True)
        return 2


def main(argv: list[str] | None = None) -> None:
    """Console entry point (``argv``: run in-process, as tests do; SIGINT is given back after)."""
    previous = _take_sigint()
    try:
        code = _run(sys.argv[1:] if argv is None else [str(a) for a in argv])
    except KeyboardInterrupt:  # at start-up, or between the command's own handlers
        code = 130
    if code == 130:
        _say_interrupted()
    _forget_unhandled_interrupt()
    if previous is not None:  # an in-process caller gets its handler back; this process is
        # done: a Ctrl-C while Python shuts down (which restores SIGINT's default, killing the
        # process with -2) is ignored
        signal.signal(signal.SIGINT, signal.SIG_IGN if argv is None else previous)
    if code:
        sys.exit(code)


if __name__ == "__main__":
    main()
