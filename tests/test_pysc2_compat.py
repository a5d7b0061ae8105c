"""pysc2 as a pysc2 user imports it, after ``import sc2data``: it works on Python 3.11, and
``import sc2data`` alone still imports none of it."""

from __future__ import annotations

import subprocess
import sys

import pytest


def run(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=False)


def test_pysc2_imports_after_import_sc2data() -> None:
    done = run("import sys, sc2data; assert 'pysc2' not in sys.modules; "
               "from pysc2.lib import features, actions; "
               "import random, inspect; assert random.shuffle.__module__ == 'random'; "
               "assert 'SCREEN_FEATURES' in inspect.getsource(features); "
               "print(features.SCREEN_FEATURES.unit_type.scale, "
               "len(features.SCREEN_FEATURES.unit_type.palette))")
    assert done.returncode == 0, done.stderr
    scale, colours = map(int, done.stdout.split())
    assert scale > 1000 and colours == scale


def test_the_palettes_are_those_sc2data_draws_with() -> None:
    """The hook leaves pysc2's colours as sc2data's own import of pysc2 makes them."""
    palette = "features.SCREEN_FEATURES.unit_type.palette[:400].sum()"
    mine = run(f"from sc2data._pysc2 import features; print({palette})")
    users = run(f"import sc2data; from pysc2.lib import features; print({palette})")
    assert mine.returncode == 0 and users.returncode == 0, mine.stderr + users.stderr
    assert mine.stdout == users.stdout


@pytest.mark.skipif(sys.version_info < (3, 11), reason="the breakage is Python 3.11's")
def test_without_the_hook_pysc2_fails_as_the_issue_says() -> None:
    """What the hook is for: plain pysc2 4.0.0 on 3.11 fails at import."""
    done = run("from pysc2.lib import features")
    assert done.returncode != 0 and "shuffle" in done.stderr
