"""The pairs: drawing matched/mismatched/null (command, state) pairs from labels, writing the pair
set and its packed splits, and reading them back for training."""
