"""Every Python block of README.md and of the guides in docs/ runs as written: the blocks
of one document in order, sharing their names, in an empty working directory, with the
data they use made by the blocks themselves or shipped in the package. A local Ray
instance stands in for the cluster that `address="auto"` joins."""

import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def blocks(document: pathlib.Path) -> list:
    return BLOCK.findall(document.read_text())


WITH_PYTHON = [d for d in DOCUMENTS if blocks(d)]


def test_the_documents_with_python_are_found():
    names = [d.name for d in WITH_PYTHON]
    assert "README.md" in names and "cluster.md" in names, names
    assert len(blocks(ROOT / "README.md")) >= 2


def test_the_shipped_example_mesh_is_the_scenes_bunny():
    shipped = ROOT / "crates" / "canopy-py" / "python" / "canopy_rt" / "data" / "bunny.ply"
    assert shipped.read_bytes() == (ROOT / "scenes" / "meshes" / "bunny.ply").read_bytes()


@pytest.fixture(scope="module")
def local_ray():
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        yield
    finally:
        ray.shutdown()


@pytest.mark.parametrize("document", WITH_PYTHON, ids=lambda d: d.name)
def test_the_python_blocks_of_a_document_run_as_written(document, tmp_path, monkeypatch, local_ray):
    monkeypatch.chdir(tmp_path)
    names = {"__name__": "__readme__"}
    for number, code in enumerate(blocks(document), 1):
        exec(compile(code, f"{document.name}, python block {number}", "exec"), names)
