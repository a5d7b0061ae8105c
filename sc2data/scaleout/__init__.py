"""Scale-out on Ray: the driver that runs rollout and label shards as Ray tasks, and the tasks."""
