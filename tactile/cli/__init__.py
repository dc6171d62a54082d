"""The `handskin` commands of tactile/: `map`, `stats`, and the dataset commands (`verify`,
`ingest`, `export`, `sheet`, ...)."""
