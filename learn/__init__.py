"""Torch models, training, evaluation and experiments. Reads dataset files and uses tactile/;
never imports sim/."""
