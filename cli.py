"""Run the sc2data command line from a checkout: ``python cli.py --help``.

The CLI itself lives in :mod:`sc2data.cli` so that installing the package never puts a generic
top-level ``cli`` module into site-packages; the installed command is ``sc2data``.
"""

from sc2data.cli import main

if __name__ == "__main__":
    main()
