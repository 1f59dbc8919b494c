"""``millwatch history``: simulated history for a store, so reports have months to show.

* ``command`` — the sub-command (``history build``): its options, help and progress bar.
* ``tiling`` — the library: one cycle per mill analysed through the real worker, its rows tiled
  over each month (``build_history``; ``tests/bench/bench_report.py`` uses its parts).
"""
