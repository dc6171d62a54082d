"""Images on the map: rasterisation and the `TactileMap` look-up table, erosion and dilation,
resizes to a network's input, hand-part labels, sensor faults."""
