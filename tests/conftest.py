import os
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)


@pytest.fixture
def run_script(tmp_path):
    """Run one of the repo's scripts in a fresh working directory, so its runs/ lands in tmp_path."""

    def run(script: str, *flags: str, timeout: float = 300) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, os.path.join(REPO, script), *flags],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=timeout,
        )

    run.cwd = tmp_path
    return run
