"""The example of docs/python.md runs as written, and its fit finds the offset it hid."""

import re
import subprocess
import sys

from conftest import REPO


def test_the_quickstart_example_runs_and_fits(tmp_path):
    p = subprocess.run(
        [sys.executable, str(REPO / "docs/examples/quickstart.py"), str(tmp_path)],
        capture_output=True,
        text=True,
        env={"MPLBACKEND": "Agg", **__import__("os").environ},
    )
    assert p.returncode == 0, p.stderr
    m = re.search(r"fitted range offset ([-+0-9.]+) m \(true ([-+0-9.]+) m\)", p.stdout)
    assert m, p.stdout
    fitted, true = float(m.group(1)), float(m.group(2))
    # a 14 ns pulse (2.1 m) in 1 ns bins with noise: a tenth of a bin's range is the aim
    assert abs(fitted - true) < 0.15, p.stdout
    assert "points from" in p.stdout and "RMSE" in p.stdout
