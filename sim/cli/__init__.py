"""The `handskin` commands of sim/: `part`, `probe`, `assets`, `generate`, `merge`, `view`."""
