"""Ending a process that has nothing left to write without the interpreter's finalization."""

from __future__ import annotations

import logging
import os
import sys


def exit_without_finalization() -> None:
    """An atexit handler: the handlers registered after it have run by then, logging's (registered at
    its import, earlier) is called here, the streams are flushed, and the module teardown is skipped:
    tearing down torch, JAX and CUDA costs a process that has nothing left to write whole seconds
    (docs/benchmarks.md)."""
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)
