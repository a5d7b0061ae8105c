"""Narrations: ordered lists of natural-language commands that shape an agent's reward.

A narration file is either TOML with one key, ``commands = ["build an SCV", …]``, or plain text
with one command per line (blank lines and lines starting with ``#`` are skipped). The default,
:data:`DEFAULT_NARRATION`, narrates BuildMarines' sub-goals in the order a player meets them.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sc2data.ground.errors import Sc2DataError

DEFAULT_NARRATION = Path(__file__).with_name("narrations") / "buildmarines.toml"
"""The BuildMarines narration shipped with sc2data."""


@dataclass(frozen=True)
class Narration:
    """An ordered, non-empty tuple of commands and where it was read from."""

    commands: tuple[str, ...]
    source: str

    def __len__(self) -> int:
        return len(self.commands)


def load_narration(path: str | Path | None = None) -> Narration:
    """Read a narration file (TOML or one command per line); None reads the default."""
    path = Path(path) if path is not None else DEFAULT_NARRATION
    if not path.is_file():
        raise Sc2DataError(f"narration file {path} does not exist")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise Sc2DataError(f"cannot read narration file {path}: {e}") from None
    if path.suffix == ".toml":
        commands = _from_toml(path, text)
    else:
        commands = [line.strip() for line in text.splitlines()
                    if line.strip() and not line.strip().startswith("#")]
    if not commands:
        raise Sc2DataError(f"narration file {path} holds no command; write one per line (or "
                           f"commands = [...] in TOML)")
    return Narration(tuple(commands), str(path))


def _from_toml(path: Path, text: str) -> list[str]:
    try:
        data: dict[str, Any] = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise Sc2DataError(f"narration file {path} is not valid TOML: {e}") from None
    unknown = sorted(set(data) - {"commands"})
    if unknown:
        raise Sc2DataError(f"narration file {path}: unknown key {unknown[0]!r}; the only key is "
                           f"'commands'")
    commands = data.get("commands", [])
    if not isinstance(commands, list) or not all(isinstance(c, str) and c.strip()
                                                 for c in commands):
        raise Sc2DataError(f"narration file {path}: 'commands' must be a list of non-empty "
                           f"strings")
    return [c.strip() for c in commands]


def check_readable(narration: Narration, scorer: Any) -> None:
    """Refuse a command with a word outside the MEM's vocabulary (the MEM would drop it silently).

    ``scorer`` is a :class:`~sc2data.model.scorer.MEMScorer`; a stand-in without ``words`` (a
    test's fake scorer) is not checked.
    """
    words = getattr(scorer, "words", None)
    if words is None:
        return
    from sc2data.model.words import tokens

    index = words.index
    for command in narration.commands:
        if not tokens(command):
            raise Sc2DataError(f"narration command {command!r} has no word")
        for word in tokens(command):
            if word not in index:
                raise Sc2DataError(f"the word {word!r} of narration command {command!r} is not "
                                   f"in the MEM's vocabulary ({len(words.words)} words); "
                                   f"rephrase it")
