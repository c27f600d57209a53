"""Starting Warp quietly: no greeting, and no 'Could not find or load the NVIDIA CUDA driver'
warning on machines without a GPU (users read it as an error; the CPU is then simply the
device). Every other line Warp's native library prints while starting is passed on."""

from __future__ import annotations

import os
import sys
import tempfile

import warp as wp

DRIVER_WARNING = b"Could not find or load the NVIDIA CUDA driver"


def init_warp() -> None:
    """wp.init(), with the driver warning filtered out of what Warp writes to stderr."""
    from warp._src import context

    wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)  # no greeting
    if context.runtime is not None:
        return
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as caught:
        os.dup2(caught.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            caught.seek(0)
            kept = [line for line in caught.read().splitlines(keepends=True)
                    if DRIVER_WARNING not in line]
            if kept:
                os.write(2, b"".join(kept))
