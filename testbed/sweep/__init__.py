"""Parameter sweeps over scenario keys: spec, backends (process pool, Dask), journal, aggregate."""
