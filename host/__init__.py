"""heliquad's host tool, by stage: ``records`` (file formats, the floor), ``process``
(signals, child processes), ``estimate`` (points and fits), ``acquire`` (links, sessions,
sweeps), ``validate`` (closed loop, truth, replay), ``present`` (plots, report),
``campaign`` (a session's identification end to end), ``study`` (many simulated campaigns
on Dask), ``commands`` (one module per command) and ``cli`` (the program and its parser). docs/architecture.md maps them."""

__version__ = "0.1.0"

__all__ = ["__version__"]
