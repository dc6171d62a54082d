"""Datasets: the run's configuration, which sample is what (hands, non-hands, several contacts),
chunks computed by worker processes or Ray, shards, and labelled contacts in memory."""
