"""Speed and quality measurements. Each script records its figures with ``benchmarks.results``."""
