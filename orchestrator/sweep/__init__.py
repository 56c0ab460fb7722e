"""Robustness sweeps on Dask: spec, draws, runs, engine, store, report, replay."""
