"""Where a command's text goes: stdout, or the file `--out` names."""

from __future__ import annotations

import sys
from pathlib import Path

from fleet.errors import UserError


def write_or_print(text: str, out: Path | None) -> bool:
    """`text` on stdout (False) or in the file `out` (True); a system error (a full disk, a
    device) is refused naming the file."""
    if out is None:
        sys.stdout.write(text)
        return False
    try:
        out.write_text(text)
    except OSError as exc:
        raise UserError(f"--out {out}: {exc.strerror}") from None
    return True
