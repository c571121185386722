"""Session-wide test settings: no test reaches the network or the user's Hugging Face cache.

Set at import, before any test module imports huggingface_hub (which reads these once): an empty hub cache
in a temporary folder and offline mode. Tests that need a cached model lay out their own cache
(``HF_HUB_CACHE`` per test); tests of the download replace the hub with a local stand-in.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

_CACHE = tempfile.mkdtemp(prefix="stylize3d-test-hf-cache-")
atexit.register(shutil.rmtree, _CACHE, ignore_errors=True)
os.environ["HF_HUB_CACHE"] = _CACHE
os.environ["HF_HUB_OFFLINE"] = "1"
os.environ.pop("HF_HOME", None)
