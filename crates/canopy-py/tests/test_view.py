"""`canopy_rt.view`: the viewer from Python serves the page behind its token, for a named
scene and for a scene built in code, shows inline in a notebook, refuses bad arguments
with the argument named, stops when asked, and prints nothing."""

import urllib.error
import urllib.request

import pytest

import canopy_rt


def get(url: str) -> tuple:
    try:
        with urllib.request.urlopen(url, timeout=60) as response:
            return response.status, response.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, ""


def test_a_named_scene_is_served_behind_its_token_until_stopped(capfd):
    viewer = canopy_rt.view("cornell", size=(32, 32), threads=1)
    try:
        assert viewer.running
        assert viewer.url.startswith("http://127.0.0.1:")
        status, page = get(viewer.url)
        assert status == 200 and "canopy view" in page
        without_token = viewer.url.split("?")[0]
        assert get(without_token)[0] == 403
        assert viewer.clients == 0
    finally:
        viewer.stop()
    assert not viewer.running
    with pytest.raises(urllib.error.URLError):
        urllib.request.urlopen(viewer.url, timeout=10)
    viewer.stop()  # a second stop does nothing
    out, err = capfd.readouterr()
    assert out == "" and err == "", "the library printed"


def test_a_scene_built_in_code_is_viewed_and_shown_inline():
    scene = canopy_rt.Scene(size=(24, 16), spp=4, name="built")
    scene.camera((0, 0, 4), (0, 0, 0), vfov=40)
    scene.add_sphere((0, 0, 0), 1.0, material=canopy_rt.lambertian((0.5, 0.5, 0.5)))
    with canopy_rt.view(scene) as viewer:
        assert get(viewer.url)[0] == 200
        inline = viewer._repr_html_()
        assert "<iframe" in inline and viewer.url.replace("&", "&amp;") in inline
        assert "running" in repr(viewer)
    assert not viewer.running


@pytest.mark.skipif(not canopy_rt.devices(), reason="no GPU adapter")
def test_a_viewer_on_the_gpu_serves_and_prints_nothing(capfd):
    with canopy_rt.view("cornell", device="gpu", size=(32, 24), spp=2, bvh="lbvh") as viewer:
        status, page = get(viewer.url)
        assert status == 200 and "canopy view" in page
    assert not viewer.running
    out, err = capfd.readouterr()
    assert out == "" and err == "", "the library printed"


@pytest.mark.parametrize(
    "keywords, named",
    [
        ({"bind": "not an address"}, "bind"),
        ({"bvh": "nope"}, "bvh"),
        ({"width": 3}, "width"),
        ({"device": "gpu", "width": 4}, "width"),
        ({"device": "gpu", "fast_triangles": True}, "fast_triangles"),
        ({"device": "tpu"}, "device"),
        ({"max_leaf_size": 0}, "max_leaf_size"),
        ({"threads": 0}, "threads"),
        ({"output_dir": "/no/such/folder"}, "output_dir"),
        ({"size": (0, 10)}, "empty"),
    ],
)
def test_bad_arguments_are_refused_naming_them(keywords, named):
    with pytest.raises(ValueError, match=named):
        canopy_rt.view("cornell", **keywords)
