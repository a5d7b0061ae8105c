"""Run the ``sc2data`` console entry point in-process, as a user runs it."""

from __future__ import annotations

import pytest


def exit_code(*args: object) -> int:
    """Run ``sc2data ARGS`` through :func:`sc2data.cli.main`; its exit status."""
    from sc2data.cli import main

    try:
        main([str(a) for a in args])
    except SystemExit as e:
        return int(e.code or 0)
    return 0


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Run ``sc2data ARGV``: (exit status, stdout, stderr)."""
    capsys.readouterr()
    code = exit_code(*argv)
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(code: int, err: str, *needles: str) -> None:
    """Exit status 2, exactly one ``sc2data: error:`` line on stderr naming ``needles``."""
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sc2data: error: "), err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], lines[0]
