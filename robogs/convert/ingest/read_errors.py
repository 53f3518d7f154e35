"""One translation of a container reader's exceptions into robogs errors.

A bag or MCAP reader raises many exception types for a damaged file (struct, EOF, zstd, its
own). Inside :func:`corrupt_source` they become one :class:`InputError` naming the file and the
last place read; robogs errors pass unchanged (an ``OutputError`` such as a full disk is never
blamed on the input), and a decompression-limit error gains the file and place.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from robogs.format.errors import InputError, RobogsError

from .decompress import DecompressionLimitError

__all__ = ["corrupt_source"]


@contextmanager
def corrupt_source(
    src: Path,
    errors: tuple[type[BaseException], ...],
    *,
    where: Callable[[], str],
    what: str,
    hint: str,
) -> Iterator[None]:
    """Translate reader exceptions raised in the block.

    Args:
        src: the source file.
        errors: the reader's exception types that mean "damaged input".
        where: returns the place reached when the error happened (read at that moment).
        what: the kind of source in the message ("MCAP", "bag").
        hint: what the user can do about a damaged file.
    """
    try:
        yield
    except DecompressionLimitError as exc:
        if exc.path:
            raise
        raise DecompressionLimitError(exc.message, path=src, where=where(), hint=exc.hint) from None
    except RobogsError:
        raise
    except errors as exc:
        raise InputError(
            f"{what} is corrupt ({type(exc).__name__}: {str(exc)[:200]})",
            path=src,
            where=where(),
            hint=hint,
        ) from None
