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

**Progressive full frames.** Where a full frame takes long (the U-Net decoder's
cost grows with the pixel count: ~1.5-2.5 s at 768x512 on a shared 2-core CPU),
RESTING renders it in *levels* (:attr:`RenderStateMachine.levels`, fractions of
the full size, e.g. ``(0.25, 1.0)``): the smaller frame through the same
decoder and every point -- sharp, with the final frame's colours -- in a
fraction of the time, then the full one. :meth:`RenderStateMachine.shown` says
when the next level is due; only the last level settles the view, and a change
at any level interrupts it. :func:`refine_levels` chooses the levels from the
last full frame's and the last first level's times: the first level is as large
(1/8 to 1/2 of the size) as fits the budget of a sharp frame after the rest.

``version`` counts changes; a frame rendered for an older version is out of
date and never settles the view. Runs on the GUI main thread only (no locks).
"""

from __future__ import annotations

import enum
import math
from typing import NamedTuple, Optional, Sequence, Tuple

from stylize3d_core.checks import check_range
from stylize3d_core.errors import InputError

REST_DELAY_S = 0.1
"""How long the camera must rest before the full frame is rendered (``PreviewSettings.rest_delay_s``): long
enough that the pauses within one drag do not start a full frame, short enough not to feel like a wait."""


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


PROGRESSIVE_LEVELS: Tuple[float, ...] = (0.5, 1.0)
"""The levels of a progressive full frame before anything is measured: half size first, then the full size."""

FIRST_LEVEL_RANGE: Tuple[float, float] = (0.125, 0.5)
"""The size fractions the first level of a progressive full frame may take (:func:`refine_levels`)."""


def level_cost_model(full: Tuple[float, float], level: Tuple[float, float]) -> Optional[Tuple[float, float]]:
    """``(a, b)`` of ``seconds ~ a + b * scale**2`` through two measured frames ``(scale, seconds)``: the
    full frame and a level. ``a`` is what every full-quality frame costs whatever its size (rasterizing
    every point), ``b`` the per-pixel part (the decoder). None when the two do not give a usable fit."""
    (s1, t1), (s2, t2) = full, level
    if not all(math.isfinite(v) for v in (s1, t1, s2, t2)) or abs(s1 * s1 - s2 * s2) < 1e-6:
        return None
    b = (t1 - t2) / (s1 * s1 - s2 * s2)
    a = t1 - b * s1 * s1
    if b <= 0.0:
        return None
    return max(0.0, a), b


def refine_levels(last_full_s: Optional[float], budget_s: float = 0.5,
                  last_level: Optional[Tuple[float, float]] = None) -> Tuple[float, ...]:
    """The levels of the next full frame.

    ``(1.0,)`` (the full size at once) when the last full frame took at most ``budget_s``; else two
    levels, a first one then the full size. The first level's scale is the largest in
    :data:`FIRST_LEVEL_RANGE` (in steps of 1/16) whose predicted time fits ``budget_s`` under
    :func:`level_cost_model` of the last full frame and ``last_level`` (``(scale, seconds)`` of the last
    first level); the smallest one when none fits, and 0.5 (:data:`PROGRESSIVE_LEVELS`) while nothing is
    measured. A first level always costs the rasterization of every point, so it is worth it only where
    the full frame itself misses the budget."""
    if last_full_s is None or not math.isfinite(last_full_s):
        return PROGRESSIVE_LEVELS
    if last_full_s <= budget_s:
        return (1.0,)
    lo, hi = FIRST_LEVEL_RANGE
    model = None if last_level is None else level_cost_model((1.0, last_full_s), last_level)
    if model is None:  # only the full frame is known: a frame costs ~ its pixels
        model = (0.0, last_full_s)
    a, b = model
    steps = [k / 16 for k in range(int(round(hi * 16)), int(round(lo * 16)) - 1, -1)]
    first = next((s for s in steps if a + b * s * s <= budget_s), steps[-1])
    return (first, 1.0)


class RenderStateMachine:
    """Which frame the live view needs and when (see the module docstring).

    Attributes:
        levels: the size fractions of the levels of a full frame, increasing, ending at 1.0 (default
            ``(1.0,)``: one level); a new value takes effect at the next change.
    """

    def __init__(self, rest_delay_s: float = REST_DELAY_S, hold_delay_s: float = 0.5,
                 levels: Sequence[float] = (1.0,)) -> None:
        self.rest_delay_s = check_range(rest_delay_s, "rest_delay_s", 0.0, 10.0)
        self.hold_delay_s = check_range(hold_delay_s, "hold_delay_s", self.rest_delay_s, 10.0)
        self.version = 0
        self.phase = RenderPhase.SETTLED
        self._changed_at = -math.inf
        self._full_version = -1  # version whose full frame was requested (RESTING) or shown / given up
        self.levels = check_levels(levels)
        self._levels = self.levels  # the levels of the current version's full frame
        self._level = 0  # index in _levels of the level requested (RESTING) or due next

    def changed(self, now: float) -> Change:
        """The view changed at ``now``: MOVING; ``interrupt`` when a full render was in progress."""
        interrupt = self.phase is RenderPhase.RESTING
        self.version += 1
        self._changed_at = now
        self.phase = RenderPhase.MOVING
        self._levels = self.levels = check_levels(self.levels)
        self._level = 0
        return Change(self.version, interrupt)

    def retarget(self, levels: Sequence[float]) -> None:
        """Use ``levels`` for the current version's full frame, while it is not requested yet (MOVING): a
        mouse release is a rest without the rest delay, so the caller chooses the levels for a larger
        budget there. Elsewhere nothing changes."""
        levels = check_levels(levels)
        if self.phase is RenderPhase.MOVING:
            self._levels, self._level = levels, 0

    def full_due(self, now: float, holding: bool = False) -> bool:
        """True once MOVING has rested ``rest_delay_s`` (``hold_delay_s`` while ``holding``: the mouse
        button is still down, a drag may go on; a busy GUI thread delivers its moves in bursts, and a
        full frame requested between two bursts would only be interrupted by the next one). The caller
        requests the full frame at :attr:`full_scale`, then calls :meth:`full_requested`."""
        delay = self.hold_delay_s if holding else self.rest_delay_s
        return self.phase is RenderPhase.MOVING and now - self._changed_at >= delay

    @property
    def full_scale(self) -> float:
        """The size fraction of the full-frame level to request next (or being rendered)."""
        return self._levels[self._level]

    @property
    def full_level(self) -> Tuple[int, int]:
        """(index, count) of that level."""
        return self._level, len(self._levels)

    def full_requested(self) -> None:
        """The full frame (its level :attr:`full_scale`) of the current version was requested: RESTING."""
        if self.phase is RenderPhase.MOVING:
            self.phase = RenderPhase.RESTING
            self._full_version = self.version

    def shown(self, version: int, preview: bool, scale: float = 1.0) -> bool:
        """A frame of ``version`` (a full frame: of level ``scale``) is on screen. The current version's
        last level settles the view; an earlier level makes the next one due: returns True, and the
        caller requests it at :attr:`full_scale` (the phase stays RESTING)."""
        if preview or version != self.version or self.phase is not RenderPhase.RESTING:
            return False
        if scale < self.full_scale - 1e-9:  # an earlier level than the one requested (not expected)
            return False
        if self._level + 1 < len(self._levels):
            self._level += 1
            return True
        self.phase = RenderPhase.SETTLED
        return False

    def full_failed(self, version: int) -> None:
        """The full frame of ``version`` could not be rendered: settle (ask again after the next change)."""
        if version == self.version and self.phase is RenderPhase.RESTING:
            self.phase = RenderPhase.SETTLED

    def full_interrupted(self, version: int) -> None:
        """The full render of ``version`` was abandoned without a change (e.g. a test hook or an export
        needing the worker): if it is still the current view, rest again and re-request it (the same
        level: the ones before it are on screen)."""
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


def check_levels(levels: Sequence[float]) -> Tuple[float, ...]:
    """``levels`` as a tuple, checked: increasing fractions in (0, 1], the last one 1.0."""
    out = tuple(float(v) for v in levels)
    if not out or out[-1] != 1.0 or any(not 0.0 < v <= 1.0 for v in out) or any(
            b <= a for a, b in zip(out, out[1:])):
        raise InputError("full-frame levels", f"need increasing fractions in (0, 1] ending at 1.0, got {levels!r}")
    return out
