"""Monte-Carlo robustness sweeps of the co-simulation on Dask (`pfnav-sweep`, docs/sweeps.md).

spec: TOML specs, factors, sampling. runner: one run on a worker. driver: planning once per
terrain seed and the runs on Dask. cluster: the Dask client. store: Parquet rows, resume.
stats: fall rates with Wilson intervals. report: markdown and plots. cli: the command line.
"""
