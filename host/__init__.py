"""heliquad's host side: logging, frequency-response estimation, fitting, reports, CLI.

Modules: ``fsf`` (FSF estimator), ``baselines`` (DFT and Welch H1), ``fit`` (Levy, SK and
output-error fitting), ``metrics`` (J, AICc, recommendation), ``identify`` (points to
models), ``files`` (file formats), ``plot``, ``demo``, ``cli``.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
