"""How much memory this machine has free now."""
from __future__ import annotations


def available_memory_bytes() -> int:
    """MemAvailable from /proc/meminfo (4 GiB when it cannot be read)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 4 << 30
