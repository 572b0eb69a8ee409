"""Resource guard: estimate a job's memory before it starts and refuse what cannot fit.

A job that outgrows the machine is killed by the kernel with no message (exit 137) after
minutes of work; an estimate made up front turns that into a one-line
:class:`~momentid.errors.ResourceError` that says how big the job is and what would fit.
"""

from __future__ import annotations

import os

from momentid.errors import ResourceError

__all__ = ["available_memory", "require_memory", "MEMORY_SHARE"]

#: Largest share of the available memory one job may plan to use.  The estimates count the
#: arrays a job holds at its peak, not the interpreter, libraries or the other process of a
#: parallel run, so half is left for those.
MEMORY_SHARE = 0.5


def available_memory() -> float:
    """Memory the system can give a new job now (bytes): ``MemAvailable`` on Linux, else total."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return float("inf")


def require_memory(needed: float, what: str, hint: str) -> None:
    """Raise :class:`ResourceError` when ``needed`` bytes exceed the share a job may use.

    Parameters
    ----------
    needed : float
        Estimated peak memory of the job (bytes).
    what : str
        The job, for the message (``"simulation of scenario 'x'"``).
    hint : str
        What would fit, for the message.
    """
    available = available_memory() * MEMORY_SHARE
    if not needed <= available:  # also refuses a NaN or infinite estimate
        raise ResourceError(what, needed, available, hint)
