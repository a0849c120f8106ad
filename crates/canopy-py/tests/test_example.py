"""The README's example runs and writes its plot."""

import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "depth_image.py"


def test_depth_image_example_writes_a_png(tmp_path):
    out = tmp_path / "depth.png"
    result = subprocess.run(
        [sys.executable, EXAMPLE, str(Path(__file__).resolve().parents[3] / "scenes" / "meshes" / "bunny.ply"), out],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "rays hit the mesh" in result.stdout
