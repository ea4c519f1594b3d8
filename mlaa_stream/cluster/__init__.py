"""Scale-out on a Dask cluster: one job's frames split into chunks, each filtered by a worker with its own
OpenCL device and written atomically, as on one machine. It sits above the pipeline (it runs it per chunk)."""
