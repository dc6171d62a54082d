"""Datasets on disk (h5py; no torch, no mujoco): schema, resumable writer, merge, splits, reader,
ingest of real recordings and PNG export. Format: ``docs/dataset_format.md``.

    writer = DatasetWriter(out, config=cfg, part=name, generator_version=v, seed=s,
                           tmap=tmap, layout=layout)
    writer.write_chunk(0, samples); writer.merge()          # synthetic (sim/generate/run.py)
    ingest_recording("layout.txt", "frames.csv", out)        # real recording
    ds = open_dataset(out); ds[0]["image"], ds.splits["train"], ds.map
    verify_dataset(out).faults                               # every damage named, with its fix
"""

from tactile.dataset.export import export_png
from tactile.dataset.folder import DATASET, INFO, chunk_path, list_chunks
from tactile.dataset.ingest import ingest_recording
from tactile.dataset.manifest import make_manifest
from tactile.dataset.merge import merge_chunks
from tactile.dataset.reader import DatasetReader, open_dataset
from tactile.dataset.schema import FIELDS, REQUIRED, Dims, FieldSpec, field_spec, validate_sample
from tactile.dataset.splits import Split, split_indices
from tactile.dataset.verify import verify_dataset
from tactile.dataset.writer import DatasetWriter

__all__ = [
    "DATASET",
    "FIELDS",
    "INFO",
    "REQUIRED",
    "DatasetReader",
    "DatasetWriter",
    "Dims",
    "FieldSpec",
    "Split",
    "chunk_path",
    "export_png",
    "field_spec",
    "ingest_recording",
    "list_chunks",
    "make_manifest",
    "merge_chunks",
    "open_dataset",
    "split_indices",
    "validate_sample",
    "verify_dataset",
]
