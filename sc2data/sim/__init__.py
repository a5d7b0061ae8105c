"""The embedded BuildMarines simulator, speaking pysc2's environment interface."""
