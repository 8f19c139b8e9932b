"""Files written whole or not at all, for every file the package writes.

A room of its own below every stage (it imports nothing of sknarx), so the
identification core can write its models atomically without importing :mod:`sknarx.io`,
which reads models back through it. Users reach it as :mod:`sknarx.io`'s.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["write_atomic", "write_text_atomic"]


def write_atomic(path, write) -> Path:
    """Write ``path`` whole or not at all: ``write(tmp)`` writes a temporary file beside
    it, which then replaces ``path`` in one step. A run stopped mid-write (killed, out of
    disk) leaves the previous file or none, never a truncated one a later run would
    read. Returns ``path``.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from sknarx.io import write_atomic
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = write_atomic(Path(d) / "a.txt", lambda tmp: Path(tmp).write_text("x"))
    ...     path.read_text(), sorted(p.name for p in Path(d).iterdir())
    ('x', ['a.txt'])
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix="." + path.name, suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        # mkstemp makes the file private (0600); the output gets the mode a plain write
        # would have given it
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def _umask() -> int:
    """The process's umask, read where the system shows it: setting it to read it back
    would, for an instant, let another thread create a file with no mask."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0)  # elsewhere: set and restore
    os.umask(mask)
    return mask


def write_text_atomic(path, text: str) -> Path:
    """:func:`write_atomic` of a text (UTF-8)."""
    return write_atomic(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
