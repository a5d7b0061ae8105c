"""Command-line options written once: shared option groups, and options derived from a config
dataclass (CleanRL's way: the config *is* the command line, its field docstrings the help).

Typer reads a command's options from its function signature; :func:`with_options` adds a group's
parameters to that signature and hands the command one value built from them, so
``--ray``/``--ray-retries``/``--ray-timeout``/``--ray-memory`` are declared here once and every
command that takes them gets the same names, defaults and help.
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import inspect
import textwrap
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional, TypeVar

import typer

F = TypeVar("F", bound=Callable[..., Any])


@dataclass(frozen=True)
class OptionGroup:
    """Several options that arrive at the command as one keyword argument ``name``."""

    name: str
    params: tuple[inspect.Parameter, ...]
    collect: Callable[[dict[str, Any]], Any]
    """Builds the command's value from the group's parsed options (by parameter name)."""


def option(name: str, annotation: Any, default: Any) -> inspect.Parameter:
    """A keyword parameter whose default is a ``typer.Option``."""
    return inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default,
                             annotation=annotation)


def with_options(*groups: OptionGroup) -> Callable[[F], F]:
    """Decorate a command: add each group's options to its signature, pass it each group's value."""

    def wrap(fn: F) -> F:
        sig = inspect.signature(fn)
        hints = typing.get_type_hints(fn)
        own = [p.replace(annotation=hints.get(p.name, p.annotation))
               for p in sig.parameters.values() if p.name not in {g.name for g in groups}]
        added = [p for g in groups for p in g.params]

        @functools.wraps(fn)
        def command(**kwargs: Any) -> Any:
            for g in groups:
                kwargs[g.name] = g.collect({p.name: kwargs.pop(p.name) for p in g.params})
            return fn(**kwargs)

        params = own + added
        command.__signature__ = sig.replace(parameters=params)  # type: ignore[attr-defined]
        command.__annotations__ = {p.name: p.annotation for p in params}
        del command.__wrapped__  # typer must see the new signature, not the wrapped one
        return command  # type: ignore[return-value]

    return wrap


def field_docs(cls: type) -> dict[str, str]:
    """Each dataclass field's docstring (the string literal right under it), by field name."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs: dict[str, str] = {}
    for node, nxt in zip(body, body[1:]):
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and \
                isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant) and \
                isinstance(nxt.value.value, str):
            docs[node.target.id] = " ".join(nxt.value.value.replace("``", "").split())
    return docs


def _cli_type(annotation: Any) -> Any:
    """``X | None`` as ``Optional[X]`` (what typer understands everywhere)."""
    args = typing.get_args(annotation)
    if isinstance(annotation, types.UnionType) and type(None) in args:
        (inner,) = [a for a in args if a is not type(None)]
        return Optional[inner]
    return annotation


def config_options(cls: type, *, arguments: Mapping[str, tuple[str, str]] = {},
                   skip: tuple[str, ...] = (), flags: Mapping[str, str] = {},
                   metavars: Mapping[str, str] = {}) -> OptionGroup:
    """One option per init field of dataclass ``cls`` (``--batch-size`` for ``batch_size``),
    typed and defaulted as the field is, its docstring as help; ``arguments`` names fields taken
    as positional arguments (their metavar, ``PAIRS``, and help), ``flags`` gives a field its own
    option spelling (``"--progress/--no-progress"``), ``metavars`` names what a field's value is
    where its type does not say (``PATH`` for a path kept as a string). The command receives a
    ``cls`` instance as ``config``."""
    hints = typing.get_type_hints(cls)
    docs = field_docs(cls)
    params = []
    for f in dataclasses.fields(cls):
        if not f.init or f.name in skip:
            continue
        if f.name in arguments:
            metavar, help_text = arguments[f.name]
            default: Any = typer.Argument(..., metavar=metavar, help=help_text)
        else:
            value = f.default if f.default is not dataclasses.MISSING else ...
            decls = [flags[f.name]] if f.name in flags else []
            default = typer.Option(value, *decls, help=docs.get(f.name, ""),
                                   metavar=metavars.get(f.name))
        params.append(option(f.name, _cli_type(hints[f.name]), default))
    return OptionGroup("config", tuple(params), lambda values: cls(**values))


def plural(n: int, word: str) -> str:
    """``1 episode``, ``2 episodes``, ``1,800 stacks``: a count and its noun, agreed."""
    return f"{n:,} {word}{'' if n == 1 else 's'}"


def _usage_name(self: Any) -> str:
    """A positional argument in the usage line as click writes it: ``DATA``, ``[DATA]``,
    ``RUN...`` (typer's own wraps a required one in braces, ``{DATA}``)."""
    name = self.metavar or self.name.upper()
    if not self.required and not name.startswith("["):
        name = f"[{name}]"
    return name + ("..." if self.nargs != 1 and not name.endswith("...") else "")


_WORDS = {int: "N", float: "NUMBER", str: "TEXT"}
"""An option's value type in the one word help shows for it."""


def _type_metavar(param: Any) -> str | None:
    """What an option's value is, in one uppercase word (``PATH``, ``N``, ``TEXT``), for an
    option that names none itself; None for a flag or a choice (help lists its values)."""
    desc = param.type_descriptor
    if param.is_flag or param.count or desc.is_choice:
        return None
    if desc.is_path:
        return "PATH"
    annotation = desc.annotation
    if desc.is_list:
        (annotation,) = typing.get_args(annotation) or (str,)
    if annotation is Path or (isinstance(annotation, type) and issubclass(annotation, Path)):
        return "PATH"
    return _WORDS.get(annotation, "TEXT")


def one_voice(command: Any) -> Any:
    """Give every command under ``command`` (typer's click command) one way of writing what it
    takes: an option's value as an uppercase word (``--out PATH``, ``--episodes N``) unless it
    names its own, a positional argument by its name in capitals (``RUN``, ``DATA``) as click
    writes them, ``RUN...`` for several. Returns ``command``."""
    from typer.core import TyperArgument

    class Argument(TyperArgument):
        _usage_display_name = _usage_name

        def display_type_rich(self, ctx: Any) -> str | None:
            return None  # its name says what it takes (``DATA``), not ``<path>``

    for param in command.params:
        if isinstance(param, TyperArgument):
            if param.metavar is None and param.name:
                param.metavar = param.name.upper() + ("..." if param.nargs != 1 else "")
            param.__class__ = Argument
        elif getattr(param, "metavar", "") is None and hasattr(param, "type_descriptor"):
            param.metavar = _type_metavar(param)
    for sub in getattr(command, "commands", {}).values():
        one_voice(sub)
    return command
