"""pysc2 4.0.0 importable on Python 3.11 wherever it is imported from, at no cost until it is.

Two known breakages of the last released pysc2 on Python 3.11, fixed by an import hook that
``import sc2data`` installs (it imports nothing itself: pysc2 still loads only when something
imports it, sc2data's own modules or the user's ``from pysc2.lib import features``):

* ``pysc2/lib/colors.py`` calls ``random.shuffle(x, fn)``, the second argument removed in 3.11,
  when ``pysc2/lib/features.py`` builds its palettes at import. While a pysc2 module executes,
  ``random.shuffle`` accepts it (pysc2 seeds that shuffle with a constant, so its palettes stay
  deterministic either way); at any other moment ``random.shuffle`` is Python's own.
* ``s2clientprotocol`` ships old generated protobuf code. We pin ``protobuf<3.21``; if another
  package forced a newer protobuf, the pure-Python implementation still loads the old code, so
  when pysc2 is first imported before protobuf, that implementation is selected.
"""

from __future__ import annotations

import importlib.machinery
import os
import sys
from collections.abc import Callable, MutableSequence, Sequence
from types import ModuleType
from typing import Any

_shuffle: Callable[..., None] | None = None
"""Python's own ``random.shuffle``, kept while the compatible one is in place."""
_depth = 0
"""pysc2 modules executing now (one imports another): the compatible shuffle is in place while
it is above zero."""


def _shuffle_compat(x: MutableSequence[Any], random_fn: Callable[[], float] | None = None) -> None:
    """``random.shuffle`` accepting pysc2's removed ``random`` argument (Fisher-Yates with it)."""
    if random_fn is None:
        assert _shuffle is not None
        _shuffle(x)
        return
    for i in reversed(range(1, len(x))):
        j = int(random_fn() * (i + 1))
        x[i], x[j] = x[j], x[i]


class _PatchedLoader:
    """Runs a pysc2 module with the old ``random.shuffle`` signature accepted."""

    def __init__(self, loader: Any) -> None:
        self._loader = loader

    def __getattr__(self, name: str) -> Any:
        """Everything else (``get_source``, ``get_resource_reader``, …) is the real loader's."""
        return getattr(self._loader, name)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self._loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        global _depth, _shuffle
        import random  # here, not at import sc2data: only pysc2's import needs it

        if not _depth:
            _shuffle = random.shuffle
            random.shuffle = _shuffle_compat  # type: ignore[assignment]
        _depth += 1
        try:
            self._loader.exec_module(module)
        finally:
            _depth -= 1
            if not _depth:
                random.shuffle = _shuffle  # type: ignore[assignment]


class _Finder:
    """Steps in for pysc2's modules only (protobuf's implementation before the first, the
    shuffle while each executes); every other import passes by untouched."""

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if fullname != "pysc2" and not fullname.startswith("pysc2."):
            return None
        if fullname == "pysc2":
            os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
            if "google.protobuf" not in sys.modules:
                os.environ.setdefault("PROTOCOL_BUFFERS_PYTHON_IMPLEMENTATION", "python")
        spec = importlib.machinery.PathFinder.find_spec(fullname, path, target)
        if spec is None or spec.loader is None:
            return None
        spec.loader = _PatchedLoader(spec.loader)
        return spec


def install() -> None:
    """Install the hook, once per process (it only ever widens ``shuffle``'s signature, so it
    is harmless on a Python that still has the old one)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.insert(0, _Finder())
