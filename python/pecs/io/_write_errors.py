"""Write failures (disk full, quota, file too large, I/O error) as OSErrors naming the target.

Python writers raise OSError; faery's Rust encoders raise RuntimeError("No space left on device
(os error 28)"), or a PanicException, with the errno only in the text.
"""

from __future__ import annotations

import errno
import os
import re
from pathlib import Path

_RUST_OS_ERROR = re.compile(r"os error (\d+)")

#: errnos that mean the data could not be stored (not a bad path or permission)
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS})


def os_error_in(error: BaseException) -> OSError | None:
    """The OSError a native encoder's exception reports in its message, if any."""
    found = _RUST_OS_ERROR.search(str(error))
    if found is None:
        return None
    code = int(found.group(1))
    return OSError(code, os.strerror(code))


def write_error(target: Path, error: OSError) -> OSError:
    """The same failure, naming the file the user asked for (not its temporary .part)."""
    if error.filename == str(target) and error.filename2 is None:
        return error  # already names it, maybe with why (pecs._atomic)
    if error.errno is None:
        return OSError(errno.EIO, f"{error}", str(target))
    return OSError(error.errno, os.strerror(error.errno), str(target))
