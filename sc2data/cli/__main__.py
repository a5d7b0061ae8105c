"""``python -m sc2data.cli``: the ``sc2data`` command."""

from sc2data.cli import main

main()
