"""Built-in labelling rules, installed as ``sc2data.rules``."""
