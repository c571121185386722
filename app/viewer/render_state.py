"""The live view's render state machine: moving preview, resting preview, full frame (pure, times passed in).

Interactive viewers of radiance fields and 3D photos (nerfstudio's viewer
renderer, viser / nerfview) drive their renders with a small explicit state
machine: low-resolution frames while the camera moves, the full-quality frame
once it rests, and any new camera change abandons a full frame in progress.
:class:`RenderStateMachine` is that machine for the viewer::

             change                    rested rest_delay_s
    SETTLED ---------> MOVING -----------------------------> RESTING
       ^                ^  |  change (preview at once)          |  |
       |                |  +-------<-------+                    |  |
       |                +---------------- change: interrupt ----+  |
       +------------------- full frame of this version shown ------+
                            (or it failed: no retry until the next change)

* **MOVING** ("moving preview"): the camera (or anything the view shows)
  changed less than ``rest_delay_s`` ago (``hold_delay_s`` while the mouse
  button is held). Every change asks for a preview at
  the adaptive preview size.
* **RESTING** ("resting preview"): the camera has rested; the full frame is
  requested and rendering while the last preview stays on screen. A change in
  this state returns ``interrupt=True``: the caller cancels the full render in
  progress (the worker checks a cancel flag between stages), so the new
  preview does not wait for it.
* **SETTLED** ("full"): the full frame of the current version is on screen.

``version`` counts changes; a frame rendered for an older version is out of
date and never settles the view. Runs on the GUI main thread only (no locks).
"""

from __future__ import annotations

import enum
import math
from typing import NamedTuple

from stylize3d_core.checks import check_range


class RenderPhase(enum.Enum):
    """The states of :class:`RenderStateMachine` (see the module docstring)."""

    MOVING = "moving preview"
    RESTING = "resting preview"
    SETTLED = "full"


class Change(NamedTuple):
    """What :meth:`RenderStateMachine.changed` asks of the caller.

    Attributes:
        version: the new version of the view.
        interrupt: a full render is in progress for an older version: cancel it.
    """

    version: int
    interrupt: bool


class RenderStateMachine:
    """Which frame the live view needs and when (see the module docstring)."""

    def __init__(self, rest_delay_s: float = 0.15, hold_delay_s: float = 0.5) -> None:
        self.rest_delay_s = check_range(rest_delay_s, "rest_delay_s", 0.0, 10.0)
        self.hold_delay_s = check_range(hold_delay_s, "hold_delay_s", self.rest_delay_s, 10.0)
        self.version = 0
        self.phase = RenderPhase.SETTLED
        self._changed_at = -math.inf
        self._full_version = -1  # version whose full frame was requested (RESTING) or shown / given up

    def changed(self, now: float) -> Change:
        """The view changed at ``now``: MOVING; ``interrupt`` when a full render was in progress."""
        interrupt = self.phase is RenderPhase.RESTING
        self.version += 1
        self._changed_at = now
        self.phase = RenderPhase.MOVING
        return Change(self.version, interrupt)

    def full_due(self, now: float, holding: bool = False) -> bool:
        """True once MOVING has rested ``rest_delay_s`` (``hold_delay_s`` while ``holding``: the mouse
        button is still down, a drag may go on; a busy GUI thread delivers its moves in bursts, and a
        full frame requested between two bursts would only be interrupted by the next one). The caller
        requests the full frame, then calls :meth:`full_requested`."""
        delay = self.hold_delay_s if holding else self.rest_delay_s
        return self.phase is RenderPhase.MOVING and now - self._changed_at >= delay

    def full_requested(self) -> None:
        """The full frame of the current version was requested: RESTING."""
        if self.phase is RenderPhase.MOVING:
            self.phase = RenderPhase.RESTING
            self._full_version = self.version

    def shown(self, version: int, preview: bool) -> None:
        """A frame of ``version`` is on screen; the current version's full frame settles the view."""
        if not preview and version == self.version and self.phase is RenderPhase.RESTING:
            self.phase = RenderPhase.SETTLED

    def full_failed(self, version: int) -> None:
        """The full frame of ``version`` could not be rendered: settle (ask again after the next change)."""
        if version == self.version and self.phase is RenderPhase.RESTING:
            self.phase = RenderPhase.SETTLED

    def full_interrupted(self, version: int) -> None:
        """The full render of ``version`` was abandoned without a change (e.g. a test hook or an export
        needing the worker): if it is still the current view, rest again and re-request it."""
        if version == self.version and self.phase is RenderPhase.RESTING:
            self.phase = RenderPhase.MOVING

    @property
    def settled(self) -> bool:
        """True when the full frame of the current version is on screen."""
        return self.phase is RenderPhase.SETTLED

    @property
    def rendering_full(self) -> bool:
        """True while the full frame of the current version is requested but not shown."""
        return self.phase is RenderPhase.RESTING
