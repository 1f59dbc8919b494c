"""Composition: per-mill worker, storage, REST API, reports, CLI."""
