"""Helpers for the tests of the solve's forked processes (test_parallel, test_tamp), in a
module of their own as sweep_cells.py is."""

from __future__ import annotations

import os


def child_pids() -> set[int]:
    """PIDs of this process's children (Linux /proc), zombies included; other tests may
    have left some (multiprocessing's resource tracker): compare with the set before."""
    me = os.getpid()
    out = set()
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            try:
                with open(f"/proc/{pid}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == me:
                out.add(int(pid))
    return out
