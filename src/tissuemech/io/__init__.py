"""Instrument export readers and dataset ingest (see dispatch.read_export and ingest.ingest_dataset)."""
