"""The training stage: the loop (`learn.train.loop.fit`), checkpoints and a run folder's state,
losses, optimisers and fine-tuning, the segmenters' encoder start, cross-validation."""
