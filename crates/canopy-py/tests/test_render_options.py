"""One settings type: canopy's render options (``canopy_job::RenderOptions``) are what
``render``, ``view``, the Ray driver and its command line take, by the same names."""

import inspect

import numpy as np
import pytest

import canopy_rt as canopy
from canopy_rt import _canopy, distributed


def keywords(function):
    return {p.name for p in inspect.signature(function).parameters.values() if p.kind is p.KEYWORD_ONLY}


def test_every_front_end_takes_every_render_option():
    options = set(canopy.RENDER_OPTIONS)
    assert {"spp", "size", "max_depth", "bvh", "width", "max_leaf_size", "fast_triangles", "threads"} <= options
    assert options <= keywords(canopy.render)
    assert options <= keywords(canopy.view)
    # A task's threads are threads_per_task.
    for driver in (distributed.render, distributed.render_frames):
        assert options - {"threads"} <= keywords(driver), driver.__name__
    parser = distributed._parser()
    for command in ("render", "frames"):
        args = parser.parse_args([command, "cornell", "-o", "x.png"] + (["--frames", "f.json"] if command == "frames" else []))
        assert options - {"threads"} <= set(vars(args)), command


def test_an_unknown_option_or_a_bad_value_is_refused_by_name():
    with pytest.raises(ValueError, match="unknown field `spx`"):
        _canopy.render("cornell", {"spx": 2})
    with pytest.raises(ValueError, match="^width: .*3"):
        canopy.render("cornell", size=(8, 8), spp=1, width=3)
    with pytest.raises(ValueError, match="max_leaf_size must be in 1..=256, not 0"):
        canopy.render("cornell", size=(8, 8), spp=1, max_leaf_size=0)
    with pytest.raises(ValueError, match="fast_triangles"):
        canopy.render("cornell", size=(8, 8), spp=1, device="gpu", fast_triangles=True)


def test_the_tree_options_render_the_same_image():
    # Every tree gives the same closest hits; the fast triangle test differs only for
    # rays within rounding of an edge.
    base = canopy.render("cornell", size=(24, 16), spp=2, seed=3)
    leaves = canopy.render("cornell", size=(24, 16), spp=2, seed=3, max_leaf_size=1, width=4)
    np.testing.assert_array_equal(base, leaves)
    fast = canopy.render("cornell", size=(24, 16), spp=2, seed=3, fast_triangles=True)
    assert np.mean(np.abs(fast - base)) < 0.01 * np.mean(base)


def test_the_command_line_passes_the_render_options(tmp_path, monkeypatch):
    given = {}
    monkeypatch.setattr(distributed, "render", lambda scene, **kw: given.update(kw))
    distributed.main(["render", "cornell", "-o", str(tmp_path / "x.png"), "--no-roulette", "--sampler",
                      "independent", "--bvh", "lbvh", "--width", "4", "--max-leaf-size", "2",
                      "--fast-triangles", "--schedule", "depth"])
    assert given["russian_roulette"] is False
    assert (given["sampler"], given["bvh"], given["width"], given["max_leaf_size"]) == ("independent", "lbvh", 4, 2)
    assert given["fast_triangles"] is True and given["schedule"] == "depth"
