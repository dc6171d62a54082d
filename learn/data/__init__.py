"""The data stage: handskin datasets and folders of images as torch datasets and in-memory
tensors, with the paper's flips and sensor faults on the fly."""
