"""The worker's side of the vector env: a worker process loads neither torch nor SB3."""

from __future__ import annotations

import subprocess
import sys


def test_a_worker_imports_neither_torch_nor_sb3() -> None:
    # What a spawned worker imports to run ``_serve``; torch would be most of its start-up.
    code = ("import sys; from sc2data.rl.games import _serve, GameConfig; "
            "GameConfig('paper').make().reset(seed=0); "
            "print(sorted(m for m in ('torch', 'stable_baselines3', 'sb3_contrib') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"
