"""One-pass evaluation: benchmark layouts (`datasets`), pure metrics (`metrics`), the benchmark
runner (`benchmark`), OpenCV peers (`peers`) and plots of the metrics' output (`plots`)."""
