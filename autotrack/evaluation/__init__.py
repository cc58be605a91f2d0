"""One-pass evaluation: benchmark layouts (`datasets`), pure metrics (`metrics`), the benchmark
runner (`benchmark`), OpenCV peers (`peers`), plots of the metrics' output (`plots`), parameter
sweeps (`sweep`) and the Dask cluster's executor for both (`distributed`)."""
