"""Studies: many simulated campaigns from one spec (``heliquad study``): the spec and its
runs (``spec``), one run as a worker makes it (``runs``), the runs on Dask (``execute``), the
table of results (``table``), and its figures and page (``present``)."""
