"""Shared helpers of the model / train / evaluate tests: tiny pair sets, tiny runs, the CLI."""

from __future__ import annotations

from pathlib import Path

import pytest

from sc2data.schema import Schema

SMALL_SCHEMA = Schema.from_names(["unit_type", "player_relative", "unit_hit_points"],
                                 ["player_relative", "camera"])
"""A few layers: fast to train on, and enough to tell every synthetic event apart."""


def tiny_pairset(path: Path, schema: Schema | None = None, **kw: object) -> Path:
    from sc2data.synthetic_pairs import write_pairset

    args = dict(states_per_command=24, null_states=40, episodes=12, seed=0)
    args.update(kw)
    return write_pairset(path, schema=schema or SMALL_SCHEMA, **args)  # type: ignore[arg-type]


def train_tiny(data: Path, out: Path, epochs: int = 2, **kw: object) -> Path:
    from sc2data.train import TrainConfig, train

    args: dict[str, object] = dict(threads=1, progress=False, vocab_size=2000)
    args.update(kw)
    return train(TrainConfig(data=str(data), out=str(out), epochs=epochs, **args))  # type: ignore


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Run ``sc2data ARGV`` in-process through the console entry point: (exit code, out, err)."""
    from sc2data.cli import main

    capsys.readouterr()
    try:
        main(argv)
        code = 0
    except SystemExit as e:
        code = int(e.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(code: int, err: str, *needles: str) -> None:
    """Exit status 2, one ``sc2data: error:`` line on stderr naming ``needles``, no traceback."""
    assert code == 2, err
    lines = [l for l in err.splitlines() if l.strip() and "Warning" not in l
             and not l.startswith("  ")]
    assert len(lines) == 1 and lines[0].startswith("sc2data: error: "), err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], lines[0]
