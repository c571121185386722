"""What the viewer's controllers (:mod:`.actions`, :mod:`.applications`) may use of the window.

The window (:class:`~stylize3d_app.viewer.window.ViewerWindow`) builds the controllers and hands itself to them as a
:class:`ViewerHost`; the controllers know the window only through this protocol, so they never import
:mod:`.window` and the window stays the only module that wires them together. Main thread only, except
:meth:`ViewerHost.post`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Dict, Optional, Protocol, Tuple

if TYPE_CHECKING:
    import open3d.visualization.gui as gui

    from .panel import Panel
    from .session import ViewerSession, ViewFrame
    from .settings import ViewerSettings
    from .state import ViewState
    from .worker import ComputeWorker


class ViewerHost(Protocol):
    """The window as its controllers see it."""

    state: "ViewState"
    """The view's state (replaced, never mutated: ``dataclasses.replace``)."""
    session: "ViewerSession"
    worker: "ComputeWorker"
    settings: "ViewerSettings"
    panel: "Panel"
    window: "gui.Window"
    image: "gui.ImageWidget"
    """The widget that shows the view."""
    em: float
    """The font size in pixels: the unit of every widget's size."""
    photos: Any
    """The other controllers (:class:`~stylize3d_app.viewer.actions.PhotoController`, ``CameraPathController``,
    ``ExportController``), for the actions that span two of them."""
    paths: Any
    exports: Any
    stats: Dict[str, Any]
    """What the window reports to a test script (``docs/architecture.md``, "Driving the viewer")."""

    def post(self, fn: Callable[[], None]) -> None:
        """Any thread: run ``fn`` on the main thread without waiting."""

    def set_status(self, text: str) -> None: ...

    def set_busy(self, text: Optional[str], fraction: Optional[float] = None) -> None: ...

    def show_error(self, what: str, error: BaseException, then: Optional[Callable[[], None]] = None) -> None: ...

    def show_dialog(self, dlg: "gui.Dialog") -> None: ...

    def close_dialog(self) -> None: ...

    def file_dialog(self, mode, title: str, filters, on_done: Callable[[str], None], default_name: str = "",
                    recent: Tuple[str, ...] = ()) -> None: ...

    def remember(self, settings: "ViewerSettings") -> None: ...

    def open_recent(self, paths: Tuple[str, ...], index: int, open_fn: Callable[[str], None]) -> None: ...

    def photo_changed(self) -> None: ...

    def view_changed(self) -> None: ...

    def request_render(self, preview: bool, camera=None, side: Optional[int] = None) -> None: ...

    def final_frame(self) -> Optional["ViewFrame"]: ...

    def set_blend(self, field: str, slider: "gui.Slider", value: float, apply: Callable[[float], Any]) -> float: ...


__all__ = ["ViewerHost"]
