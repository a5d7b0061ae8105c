"""The labels: the rule registry (built-ins, plugins, rule folders) and the labelling run that
marks which stacks satisfy which command. The rule API itself is :mod:`sc2data.rulebase`."""
