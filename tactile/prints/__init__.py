"""The statistics of prints: per-sample measures of a set of prints, published measurements of
real hands, `handskin stats` and its pictures, how a print moves."""
