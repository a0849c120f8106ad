"""`canopy_rt.view`: a scene in the browser while it renders (the viewer of ``canopy view``)."""

import html
from typing import Optional, Sequence, Tuple

from . import _canopy


class Viewer:
    """A running viewer. ``url`` is the page's address (with its token); ``stop()`` ends
    it (so does leaving a ``with`` block, or the object being collected). In a Jupyter
    notebook it shows the page inline."""

    def __init__(self, native):
        self._native = native

    @property
    def url(self) -> str:
        """The page's address, token included: open it in a browser."""
        return self._native.url

    @property
    def clients(self) -> int:
        """Pages connected now."""
        return self._native.clients

    @property
    def running(self) -> bool:
        return self._native.running

    def stop(self) -> None:
        """Stops serving and rendering; nothing happens when it has stopped already."""
        self._native.stop()

    def __enter__(self) -> "Viewer":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def __repr__(self) -> str:
        state = "running" if self.running else "stopped"
        return f"Viewer({self.url!r}, {state})"

    def _repr_html_(self) -> str:
        url = html.escape(self.url, quote=True)
        return (f'<iframe src="{url}" width="100%" height="620" style="border:0"></iframe>'
                f'<div><a href="{url}" target="_blank">{url}</a></div>')
