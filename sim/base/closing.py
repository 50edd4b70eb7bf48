"""What holds something that must be closed (a firmware process, a port, a log), as a
``with`` block closes it: the one place a resource's ``close`` meets the block's end."""

from __future__ import annotations

__all__ = ["Closing"]


class Closing:
    """A base for what must be closed: ``with X(...) as x:`` closes it on the way out,
    whatever ended the block (an error, Ctrl-C). A subclass defines :meth:`close`."""

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
