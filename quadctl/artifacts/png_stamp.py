"""A figure's provenance inside its PNG: the hash of the config that made it, as a text chunk.

A JSON or NPZ artifact carries its ``config_hash``; a figure carries it in a PNG ``tEXt`` chunk
(keyword :data:`KEYWORD`, written after the image header, read by any PNG tool: ``exiftool``,
``pngcheck -t``, PIL's ``Image.info``). So a run folder can tell quadctl's figures of another config
from a figure a user put there (:mod:`quadctl.artifacts.run_folder`): one without the chunk is never
taken for quadctl's.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

SIGNATURE = b"\x89PNG\r\n\x1a\n"
"""The eight bytes every PNG starts with."""
KEYWORD = b"quadctl config_hash"
"""The ``tEXt`` chunk's keyword (PNG keywords: 1 to 79 Latin-1 characters)."""
READ_LIMIT = 1 << 16
"""Bytes read to find the chunk: it follows the 25-byte header (chunks before the image data only)."""


def stamp_png(png: bytes, config_hash: str) -> bytes:
    """``png`` with a ``tEXt`` chunk naming ``config_hash`` after its header (``IHDR``), the image unchanged.

    Raises
    ------
    ValueError
        ``png`` is not a PNG (no signature, or no header chunk first).

    Examples
    --------
    >>> import io
    >>> from matplotlib.figure import Figure
    >>> buf = io.BytesIO(); Figure(figsize=(1, 1)).savefig(buf, format="png")
    >>> stamped(stamp_png(buf.getvalue(), "ab" * 32)) == "ab" * 32
    True
    """
    if not png.startswith(SIGNATURE) or png[12:16] != b"IHDR":
        raise ValueError("not a PNG image (no signature and header)")
    header_end = 8 + 12 + struct.unpack(">I", png[8:12])[0]
    body = b"tEXt" + KEYWORD + b"\0" + config_hash.encode("ascii")
    chunk = struct.pack(">I", len(body) - 4) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
    return png[:header_end] + chunk + png[header_end:]


def stamped(png: bytes) -> str | None:
    """The ``config_hash`` a PNG's :data:`KEYWORD` chunk names, from its first bytes (None: none, or not
    a PNG)."""
    if not png.startswith(SIGNATURE):
        return None
    at = 8
    while at + 8 <= len(png):
        length, kind = struct.unpack(">I4s", png[at:at + 8])
        data = png[at + 8:at + 8 + length]
        if kind in (b"IDAT", b"IEND") or len(data) < length:
            return None
        if kind == b"tEXt":
            keyword, _, text = data.partition(b"\0")
            if keyword == KEYWORD:
                return text.decode("latin-1") or None
        at += 12 + length
    return None


def stamp_of(path: Path | str) -> str | None:
    """:func:`stamped` of the PNG file at ``path`` (None: unreadable)."""
    try:
        with open(path, "rb") as fh:
            return stamped(fh.read(READ_LIMIT))
    except OSError:
        return None
