"""The inference stage: fast CPU paths, int8 HandsNet, ensembles and test-time flips, and
prediction of a sample, a taxel frame or an image."""
