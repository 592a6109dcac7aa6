"""hockle's user-facing benchmarks: the sections of the benchmark report
(docs/benchmarks.md, ``python -m benchmarks.report``), the README's headline figures, the
service's load benchmarks, and two tools: ``compare_results`` (result files bit for bit)
and ``compile_time`` (the kernels' first compilation).

Each module runs from the repository's root as ``python -m benchmarks.NAME [options]``;
they import one another as ``benchmarks.NAME``. Not installed with hockle (pyproject.toml
packages solver, service, worker and hockle). The research instruments behind the docs'
prose are in ``research/`` (research/README.md).
"""
