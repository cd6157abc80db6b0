"""``with obj:`` for the objects that hold something to close (a port, a socket, a file).

One mixin instead of the same ``__enter__`` / ``__exit__`` pair in each: entering returns the
object, leaving calls its :meth:`close`, whatever ended the block.
"""

from __future__ import annotations

from types import TracebackType
from typing import Self


class ClosedOnExit:
    """Mix in for ``with``: the class defines :meth:`close` (idempotent, as each does)."""

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
