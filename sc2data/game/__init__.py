"""The game: BuildMarines environments (the embedded simulator in ``sim/`` or the real game through
pysc2), the agents that play it, the screen geometry they read, and frame rendering."""
