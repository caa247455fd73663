"""Run a snippet in a new Python interpreter: what a module imports shows only in a fresh ``sys.modules``."""

from __future__ import annotations

import subprocess
import sys


def run_python(code: str, timeout: float = 300.0) -> str:
    """Run ``code`` with this interpreter, environment and working directory; its stdout, stripped.

    Parameters
    ----------
    code : str
        Python source.
    timeout : float
        Limit [s] (a first import of the numerics may compile them).
    """
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout, check=True)
    return out.stdout.strip()
