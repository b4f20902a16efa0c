"""Reference systems, log writers and result comparisons that the tests and the benchmarks share. No run of the
pipeline imports them: they live in the package so that both import them by name, without path tricks."""
