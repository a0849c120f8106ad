"""`canopy view` in headless Chromium (Debian's, driven by Playwright): the page loads and
shows frames, a drag orbits (the image changes), another builder rebuilds the tree (its
statistics change), the heat map and the tree's boxes show, a click lists the picked ray's walk, and a
the tree's view descends a level, the image is saved, and a screenshot is saved into the
test's output folder.

Every wait is on an event of the page (`window.canopyView` counts what it received),
never on a fixed time, so that it passes on a busy machine.

Needs: CANOPY_BIN (the `canopy` binary), a Chromium (CANOPY_CHROMIUM, else
/usr/bin/chromium; `scripts/install-chromium.sh` installs Debian's), and Playwright.
"""

import os
import shutil
import signal
import subprocess
from pathlib import Path

import pytest

playwright = pytest.importorskip("playwright.sync_api")

CANOPY = os.environ.get("CANOPY_BIN") or shutil.which("canopy")
CHROMIUM = os.environ.get("CANOPY_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
OUT = Path(os.environ.get("CANOPY_TEST_OUT", "target/view-browser"))
# Long enough for a loaded machine; only a failing test waits this long.
PATIENCE_MS = 180_000


@pytest.fixture
def viewer():
    if not CANOPY:
        pytest.fail("set CANOPY_BIN to the canopy binary")
    if not Path(CHROMIUM).exists():
        pytest.fail(f"no Chromium at {CHROMIUM}: run scripts/install-chromium.sh")
    OUT.mkdir(parents=True, exist_ok=True)
    for old in OUT.glob("paper-1-*.png"):
        old.unlink()
    process = subprocess.Popen(
        [CANOPY, "view", "paper-1", "--size", "320x240", "--spp", "4096", "--threads", "1",
         "--output-dir", str(OUT)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        url = None
        for line in process.stdout:
            if line.strip().startswith("http://"):
                url = line.strip()
                break
        assert url, f"canopy view printed no address: {process.stderr.read()}"
        yield url
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=60)
        except subprocess.TimeoutExpired:
            process.kill()
            raise
    assert process.returncode == 130, process.stderr.read()


def image_signature(page):
    """A sum over the shown image's pixels: changes when the image does."""
    return page.evaluate(
        """() => {
            const c = document.getElementById('image');
            const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
            let s = 0;
            for (let i = 0; i < d.length; i += 7) s = (s * 31 + d[i]) % 1000000007;
            return s;
        }"""
    )


def wait_for(page, condition):
    page.wait_for_function(condition, timeout=PATIENCE_MS)


def test_the_page_renders_orbits_rebuilds_shows_the_heat_map_and_explores(viewer):
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 1000, "height": 640})
            page.set_default_timeout(PATIENCE_MS)
            page.goto(viewer)

            # First frames: a preview, then full-size passes.
            wait_for(page, "window.canopyView.frames >= 1 && window.canopyView.tree")
            wait_for(page, "!window.canopyView.lastFrame.preview && window.canopyView.lastFrame.spp >= 2")
            before = image_signature(page)
            generation = page.evaluate("window.canopyView.lastFrame.generation")

            # Drag to orbit: a new generation of frames, and another image.
            box = page.locator("#image").bounding_box()
            x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
            page.mouse.move(x, y)
            page.mouse.down()
            page.mouse.move(x + 120, y + 20, steps=6)
            page.mouse.up()
            wait_for(
                page,
                f"window.canopyView.lastFrame.generation > {generation} && !window.canopyView.lastFrame.preview",
            )
            assert image_signature(page) != before, "the image did not change after orbiting"

            # Another builder: the tree is rebuilt and its statistics change.
            tree = page.evaluate("window.canopyView.tree")
            assert tree["builder"] == "binned-sah"
            page.select_option("#builder", "sort-x")
            wait_for(page, "window.canopyView.tree.builder === 'sort-x'")
            rebuilt = page.evaluate("window.canopyView.tree")
            assert (rebuilt["sah"], rebuilt["nodes"]) != (tree["sah"], tree["nodes"])
            assert "sort-x" in page.inner_text("#tree")

            # The heat map, then the render with the tree's boxes over it.
            page.select_option("#mode", "heatmap")
            wait_for(page, "window.canopyView.lastFrame.mode === 'heatmap'")
            page.select_option("#mode", "boxes")
            wait_for(page, "window.canopyView.lastFrame.mode === 'boxes' && window.canopyView.lastFrame.spp >= 8")

            # A click lists the primary ray's walk through the tree.
            page.mouse.click(x, y)
            wait_for(page, "window.canopyView.walk && window.canopyView.walk.steps.length > 0")
            assert page.locator("#walk div").count() > 0
            assert "pixel (" in page.inner_text("#pick")
            assert not page.evaluate("window.canopyView.errors.length")

            # The tree's view: a click on an inner node's row descends to its children.
            wait_for(page, "window.canopyView.node && window.canopyView.node.children.length > 0")
            page.locator("#node tr.inner").first.click()
            wait_for(page, "window.canopyView.node.index !== null")

            # Save: a PNG in the viewer's folder.
            page.click("#save-png")
            wait_for(page, "window.canopyView.saved.length === 1")
            saved = Path(page.evaluate("window.canopyView.saved[0]"))
            assert saved.name == "paper-1-001.png" and saved.stat().st_size > 0

            page.screenshot(path=str(OUT / "view.png"))
        finally:
            browser.close()
    assert (OUT / "view.png").stat().st_size > 0
