"""The generated MAVLink dialect (firmware/mavlink/heliquad.xml, built by mavgen at install)."""

from __future__ import annotations

from .errors import InputError

__all__ = ["dialect"]


def dialect():
    """The generated module ``heliquad._mavlink``; a clear error if the build did not make it."""
    try:
        from .. import _mavlink
    except ImportError:
        raise InputError("the MAVLink dialect module is missing: reinstall heliquad "
                         "(pip install .) so the build generates it") from None
    return _mavlink
