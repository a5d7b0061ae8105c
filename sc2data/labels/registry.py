"""Find, validate and select labelling rules, the way pytest finds its plugins.

Rules come through one door, the entry-point group ``sc2data.rules``: the built-ins (``builtin =
"sc2data.rules"`` in sc2data's own pyproject) exactly like a third-party package's. An entry point
names a module exposing ``RULES`` (rule objects or no-argument :class:`~sc2data.rulebase.Rule`
subclasses), or a single rule object or class (``pkg.mod:MyRule``). A ``--rules-dir`` folder adds
its ``*.py`` files, each exposing ``RULES`` or module-level rule objects.

Every rule is checked when it loads — id format, unique id, text and version, real schema keys
in ``requires``, and a call on a small synthetic batch that must answer a ``(B,)`` bool array
without reading undeclared keys — and a bad one stops the load with a one-line
:class:`RuleError` naming it and its source. A plugin cannot end the process either: a
``sys.exit`` while its module imports, its class is built or a rule runs is such an error too.

Rules run on a read-only batch (:func:`call` hands each rule its own view of the arrays, not
writeable), so no rule can change what a later rule sees; a rule that tries is named.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import inspect
import sys
import types
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.ground.errors import Sc2DataError
from sc2data.rulebase import RULE_ID, Rule, describe, is_schema_key, synthetic_batch
from sc2data.schema import MissingLayerError, StackBatch

GROUP = "sc2data.rules"
"""The entry-point group rules are registered under."""


class RuleError(Sc2DataError):
    """A rule that cannot be loaded, validated, selected or run; the message names it."""


@dataclass(frozen=True)
class Registered:
    """A validated rule and where it came from."""

    rule: Rule
    source: str
    """Human-readable origin: ``sc2data 0.1.0 (entry point builtin: sc2data.rules)`` or a file."""
    code_sha256: str
    """Hash of the file defining the rule's code: labels made by other code are not resumed."""

    @property
    def id(self) -> str:
        return self.rule.id

    def to_dict(self) -> dict[str, Any]:
        r = self.rule
        return {"id": r.id, "version": r.version, "command": r.command,
                "requires": list(r.requires), "source": self.source,
                "code_sha256": self.code_sha256}


class Registry:
    """Validated rules by id, in load order (entry points first, then ``--rules-dir`` files)."""

    def __init__(self, entries: Iterable[Registered] = ()) -> None:
        self._by_id: dict[str, Registered] = {}
        for e in entries:
            self.add(e)

    def add(self, entry: Registered) -> None:
        old = self._by_id.get(entry.id)
        if old is not None:
            raise RuleError(f"rule id {entry.id!r} is defined twice: by {old.source} and by "
                            f"{entry.source}; rename one of them (ids must be unique)")
        self._by_id[entry.id] = entry

    def __iter__(self) -> Iterator[Registered]:
        return iter(self._by_id.values())

    def __len__(self) -> int:
        return len(self._by_id)

    def __contains__(self, rule_id: object) -> bool:
        return rule_id in self._by_id

    @property
    def ids(self) -> tuple[str, ...]:
        return tuple(self._by_id)

    def get(self, rule_id: str) -> Registered:
        self._check_known([rule_id])
        return self._by_id[rule_id]

    def select(self, include: Sequence[str] | None = None,
               exclude: Sequence[str] = ()) -> list[Registered]:
        """The rules named in ``include`` (all when None), minus ``exclude``, in load order."""
        self._check_known([*(include or ()), *exclude])
        chosen = [e for e in self if (include is None or e.id in include) and e.id not in exclude]
        if not chosen:
            raise RuleError("no rules selected; check --rules and --exclude (known: "
                            f"{', '.join(self.ids)})")
        return chosen

    def _check_known(self, ids: Iterable[str]) -> None:
        unknown = [i for i in ids if i not in self._by_id]
        if unknown:
            raise RuleError(f"unknown rule id{'s' if len(unknown) > 1 else ''} "
                            f"{', '.join(map(repr, unknown))}; known rules: "
                            f"{', '.join(self.ids) or '(none)'}")


def parse_ids(text: str | None) -> list[str] | None:
    """``"a, b,c"`` → ``["a", "b", "c"]``; None or blank → None."""
    if text is None or not text.strip():
        return None
    return [p.strip() for p in text.split(",") if p.strip()]


# -- loading -----------------------------------------------------------------------------------

def load_registry(rules_dir: Path | str | None = None, *,
                  entry_points: bool = True) -> Registry:
    """All rules from the ``sc2data.rules`` entry points and ``rules_dir``, validated."""
    registry = Registry()
    if entry_points:
        eps = sorted(metadata.entry_points(group=GROUP),
                     key=lambda ep: (_dist_name(ep) != "sc2data", _dist_name(ep), ep.name))
        for ep in eps:
            for entry in _load_entry_point(ep):
                registry.add(entry)
    if rules_dir is not None:
        for entry in load_rules_dir(rules_dir):
            registry.add(entry)
    return registry


def _dist_name(ep: metadata.EntryPoint) -> str:
    return ep.dist.name if ep.dist is not None else ""


def _load_entry_point(ep: metadata.EntryPoint) -> list[Registered]:
    dist = f"{ep.dist.name} {ep.dist.version}" if ep.dist is not None else "an unknown package"
    source = f"{dist} (entry point {ep.name}: {ep.value})"
    try:
        obj = ep.load()
    except SystemExit as e:  # at import: it would end this command silently, with its code
        raise RuleError(f"rule plugin {source} called sys.exit({e.code!r}) while it was "
                        f"imported; a rule plugin defines rules, fix or uninstall it") from None
    except Exception as e:  # a plugin's import error must not become our traceback
        raise RuleError(f"rule plugin {source} failed to import: {type(e).__name__}: {e}; fix "
                        f"or uninstall it") from e
    if isinstance(obj, types.ModuleType):
        if not hasattr(obj, "RULES"):
            raise RuleError(f"rule plugin {source} names module {obj.__name__}, which has no "
                            f"RULES; define RULES = [...] there or point the entry point at a rule")
        return _register(obj.RULES, source, what="RULES")
    return _register([obj], source, what=ep.value)


def load_rules_dir(rules_dir: Path | str) -> list[Registered]:
    """The rules defined by the ``*.py`` files of a folder (files starting with ``_`` skipped)."""
    folder = Path(rules_dir)
    if not folder.is_dir():
        raise RuleError(f"--rules-dir {folder} is not a folder; give a folder of rule .py files")
    entries: list[Registered] = []
    for path in sorted(folder.glob("*.py")):
        if path.name.startswith("_"):
            continue
        module = _import_file(path)
        if hasattr(module, "RULES"):
            entries += _register(module.RULES, f"file {path}", what="RULES")
            continue
        found = [v for v in vars(module).values()
                 if isinstance(v, Rule) and v.__module__ == module.__name__]
        if not found:
            raise RuleError(f"rule file {path} defines no rules; define RULES = [...] or "
                            f"module-level rule objects")
        entries += _register(found, f"file {path}", what="its rule objects")
    return entries


def _import_file(path: Path) -> types.ModuleType:
    digest = hashlib.sha1(str(path.resolve()).encode()).hexdigest()[:10]
    name = f"sc2data_rules_dir.{path.stem}_{digest}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise RuleError(f"rule file {path} cannot be imported as a Python module")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses and pickling look modules up here
    try:
        spec.loader.exec_module(module)
    except SystemExit as e:  # at import: it would end this command silently, with its code
        del sys.modules[name]
        raise RuleError(f"rule file {path} called sys.exit({e.code!r}) while it was imported; "
                        f"a rule file defines rules, remove the call") from None
    except Exception as e:
        del sys.modules[name]
        raise RuleError(f"rule file {path} failed to import: {type(e).__name__}: {e}") from e
    return module


def _register(objs: Any, source: str, *, what: str) -> list[Registered]:
    if isinstance(objs, (str, bytes)) or not isinstance(objs, Iterable):
        raise RuleError(f"{what} of {source} must be a list of rules, not "
                        f"{type(objs).__name__}")
    entries = []
    for obj in objs:
        rule = _instantiate(obj, source)
        validate(rule, source)
        entries.append(Registered(rule, source, _code_sha256(rule)))
    return entries


def _instantiate(obj: Any, source: str) -> Rule:
    if inspect.isclass(obj):
        try:
            return obj()
        except SystemExit as e:
            raise RuleError(f"rule class {obj.__name__} from {source} called sys.exit({e.code!r}) "
                            f"when built; a rule returns a bool array") from None
        except Exception as e:
            raise RuleError(f"rule class {obj.__name__} from {source} cannot be built with no "
                            f"arguments ({type(e).__name__}: {e}); list an instance instead") from e
    return obj


def _code_sha256(rule: Rule) -> str:
    target = rule.fn if hasattr(rule, "fn") else type(rule)
    try:
        return hashlib.sha256(Path(inspect.getfile(target)).read_bytes()).hexdigest()
    except (TypeError, OSError):
        return "unknown"


# -- validation ----------------------------------------------------------------------------------

def validate(rule: Any, source: str) -> None:
    """Raise :class:`RuleError` naming the rule and its source unless it keeps the Rule contract."""
    name = f"rule {describe(rule)} from {source}"
    rid = getattr(rule, "id", None)
    if not isinstance(rid, str) or not RULE_ID.match(rid):
        raise RuleError(f"{name} has id {rid!r}; an id must be snake_case "
                        f"(lowercase letters, digits, single underscores), e.g. build_scv")
    command = getattr(rule, "command", None)
    if not isinstance(command, str) or not command.strip():
        raise RuleError(f"{name} has no command text; set command = \"<canonical text>\"")
    version = getattr(rule, "version", None)
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise RuleError(f"{name} has version {version!r}; a version is an integer ≥ 1")
    requires = getattr(rule, "requires", None)
    if isinstance(requires, str) or not isinstance(requires, (tuple, list)) or not requires:
        raise RuleError(f"{name} must list the schema keys it reads in requires, e.g. "
                        f"(\"screen/unit_type\", \"player\")")
    bad = [k for k in requires if not isinstance(k, str) or not is_schema_key(k)]
    if bad:
        raise RuleError(f"{name} requires unknown schema key{'s' if len(bad) > 1 else ''} "
                        f"{', '.join(map(repr, bad))}; use screen/<layer>, minimap/<layer> "
                        f"(pysc2 names) or player, score_cumulative, game_loop")
    if not callable(rule):
        raise RuleError(f"{name} is not callable; define __call__(self, batch) -> (B,) bool")
    for size in (5, 1):
        check_output(rule, source, call(rule, source, synthetic_batch(requires, size)), size,
                     where="a synthetic batch")


def read_only(batch: Any) -> Any:
    """A :class:`StackBatch` of read-only views of ``batch``'s arrays (shared memory, nothing
    copied); anything else as it is."""
    if not isinstance(batch, StackBatch):
        return batch
    views = {}
    for k, a in batch.arrays.items():
        v = a.view() if isinstance(a, np.ndarray) else np.asarray(a)
        v.flags.writeable = False
        views[k] = v
    return StackBatch(views, batch.schema)


def call(rule: Rule, source: str, batch: Any, where: str = "a synthetic batch") -> Any:
    """``rule(batch)`` on a read-only view of ``batch`` (its own, so that neither its arrays nor
    its keys change what a later rule sees), with any exception turned into a one-line
    :class:`RuleError`."""
    try:
        return rule(read_only(batch))
    except ValueError as e:
        if "read-only" not in str(e):
            raise RuleError(f"rule {rule.id!r} from {source} raised ValueError: {e} on "
                            f"{where}") from e
        raise RuleError(f"rule {rule.id!r} from {source} wrote into the batch it was given "
                        f"({e}) on {where}; a rule must not change its input: copy an array "
                        f"before changing it (np.array(batch.layer(...)))") from None
    except MissingLayerError as e:
        raise RuleError(f"rule {rule.id!r} from {source} reads data it does not list in requires "
                        f"{tuple(rule.requires)} ({e}) on {where}; add the key to requires") from e
    except SystemExit as e:  # a rule must answer, not end the run (silently, with its code)
        raise RuleError(f"rule {rule.id!r} from {source} called sys.exit({e.code!r}) on {where}; "
                        f"a rule returns a bool array") from None
    except Exception as e:
        raise RuleError(f"rule {rule.id!r} from {source} raised {type(e).__name__}: {e} on "
                        f"{where}") from e


def check_output(rule: Rule, source: str, out: Any, size: int, where: str) -> np.ndarray:
    """The rule's answer if it is a ``(size,)`` bool array, else a :class:`RuleError`."""
    if not isinstance(out, np.ndarray) or out.shape != (size,) or out.dtype != np.bool_:
        got = (f"{out.dtype} array of shape {out.shape}" if isinstance(out, np.ndarray)
               else type(out).__name__)
        raise RuleError(f"rule {rule.id!r} from {source} returned {got} for {size} stacks "
                        f"({where}); a rule must return a ({size},) bool array")
    return out


def format_rules(entries: Iterable[Registered]) -> str:
    """A plain-text table of rules: id, version, command, source."""
    rows = [("ID", "VERSION", "COMMAND", "SOURCE")]
    rows += [(e.id, str(e.rule.version), e.rule.command, e.source) for e in entries]
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    return "\n".join(f"{r[0]:<{widths[0]}}  {r[1]:>{widths[1]}}  {r[2]:<{widths[2]}}  {r[3]}"
                     for r in rows)
