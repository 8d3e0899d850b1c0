"""Plots of one run and of sweeps, and the closed forms they draw (matplotlib only here).

- :mod:`~testbed.report.figures` — what every figure shares: resolution, saving, panel notes.
- :mod:`~testbed.report.run_plots` — a run's ``speeds.png``, ``state.png``,
  ``attitude_errors.png`` and :func:`~testbed.report.run_plots.write_plots`.
- :mod:`~testbed.report.timeline` — a run's link timeline, ``timeline.png``.
- :mod:`~testbed.report.images` — a run's image strip, ``images.png``.
- :mod:`~testbed.report.sweep_results` — a sweep's ``results.csv`` as the plots read it.
- :mod:`~testbed.report.sweep_axes` — per-x median lines, t intervals, the log BER axis.
- :mod:`~testbed.report.sweep_plots` — a sweep's BER plots.
- :mod:`~testbed.report.pair_plots` — any ``results.csv`` column against another, ``testbed plot``.
- :mod:`~testbed.report.closed_forms` — PER, command age and image rate under bit errors.
"""
