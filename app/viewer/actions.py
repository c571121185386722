"""What the viewer window does besides showing the view, as three controllers it is composed of:

* :class:`PhotoController` (:mod:`.photo_controller`): open photos and styles, the depth
  source and its edge alignment, the sample, and encoding the photo for the model;
* :class:`CameraPathController` (:mod:`.path_controller`): the trajectory, the camera-path
  preview (:class:`~stylize3d_app.viewer.state.Playback`), the keyframe editor, loading and
  saving camera paths;
* :class:`ExportController` (:mod:`.export_controller`): video export with progress and
  Cancel, screenshots.

Their base, :class:`Controller` and the :func:`ui_callback` wrapper, is in :mod:`.controller`;
this module gathers the controllers for the window and the tests.

They keep no app state of their own: everything lives in the window's
:class:`~stylize3d_app.viewer.state.ViewState`, which they replace (the export's cancel
event is the one exception: a thread handle, not state). They use the window
through its small public surface: ``state``, ``panel``, ``session``, ``worker``,
``post``, ``set_status``/``set_busy``, ``show_error``, ``view_changed``,
``request_render``, ``photo_changed``, ``final_frame`` and ``file_dialog``
(:class:`~stylize3d_app.viewer.host.ViewerHost`).

Their methods run on the GUI main thread; the work they start (reading files,
building the 3D photo, encoding, exporting) runs on the compute worker, whose
results come back through ``window.post`` (``post_to_main_thread``). Errors
become dialogs; what was loaded stays loaded.
"""

from .controller import DEPTH_FILTERS, IMAGE_FILTERS, JSON_FILTERS, Controller, ui_callback
from .export_controller import ExportController
from .path_controller import CameraPathController
from .photo_controller import BUNDLED_STYLES, MAX_STRIP, PhotoController, style_thumbnail

__all__ = [
    "BUNDLED_STYLES", "DEPTH_FILTERS", "IMAGE_FILTERS", "JSON_FILTERS", "MAX_STRIP", "CameraPathController",
    "Controller", "ExportController", "PhotoController", "style_thumbnail", "ui_callback",
]
