"""``keep_freed_memory``: glibc keeps freed blocks for the next allocation instead of fresh zeroed pages."""

import subprocess
import sys

import pytest

_LOOP = """
import resource, sys
import numpy as np
from stylize3d_core.memory import keep_freed_memory
kept = keep_freed_memory() if sys.argv[1] == "keep" else None
a = np.empty(64 << 20, np.uint8); a[::4096] = 1; del a  # the first touch faults either way
r0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(4):
    a = np.empty(64 << 20, np.uint8); a[::4096] = 1; del a
print(kept, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - r0)
"""


def _faults(mode: str):
    out = subprocess.run([sys.executable, "-c", _LOOP, mode], capture_output=True, text=True, check=True).stdout
    kept, faults = out.split()
    return kept, int(faults)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_freed_memory_is_reused_without_new_page_faults():
    kept, with_keep = _faults("keep")
    _, without = _faults("default")
    assert kept == "True"
    # 4 x 64 MB allocated, touched and freed: by default each is a fresh mmap whose pages fault again
    assert without > 1000 and with_keep < without / 4, (with_keep, without)
