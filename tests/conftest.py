import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from zenoh_helpers import Service


@pytest.fixture
def service(tmp_path):
    """A running reservation service process (killed after the test if still alive)."""
    svc = Service(tmp_path, f"t{os.getpid()}")
    svc.start()
    yield svc
    if svc.proc.poll() is None:
        svc.kill()
