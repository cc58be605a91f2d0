"""Several targets at once: `MultiTracker` (`multi`) on threads or child processes
(`target_process`), speculative updates (`speculation`) and kernel warm-up (`warmup`)."""
