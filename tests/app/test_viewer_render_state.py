"""The live view's render state machine (app/viewer/render_state.py): moving preview, resting preview, full."""

from __future__ import annotations

import pytest

from stylize3d_app.viewer.render_state import (
    PROGRESSIVE_LEVELS, RenderPhase, RenderStateMachine, level_cost_model, refine_levels,
)
from stylize3d_core.errors import InputError


def test_preview_while_moving_then_full_after_rest():
    s = RenderStateMachine(rest_delay_s=0.15)
    assert s.version == 0 and s.phase is RenderPhase.SETTLED
    c = s.changed(10.0)
    assert c.version == 1 and not c.interrupt and s.phase is RenderPhase.MOVING
    assert not s.full_due(10.1) and s.full_due(10.15)
    s.changed(10.12)  # still moving: the rest timer restarts
    assert not s.full_due(10.2) and s.full_due(10.3)
    s.full_requested()
    assert s.phase is RenderPhase.RESTING and s.rendering_full
    assert not s.full_due(11.0) and not s.settled
    s.shown(s.version, preview=True)  # a late preview keeps it resting
    assert s.phase is RenderPhase.RESTING
    s.shown(s.version, preview=False)
    assert s.settled and s.phase is RenderPhase.SETTLED and not s.full_due(20.0)


def test_a_change_while_the_full_frame_renders_interrupts_it():
    s = RenderStateMachine(rest_delay_s=0.15)
    s.changed(0.0)
    s.full_requested()
    assert s.phase is RenderPhase.RESTING
    c = s.changed(1.0)  # a second drag starts while the first rest's full frame renders
    assert c.interrupt and c.version == 2 and s.phase is RenderPhase.MOVING
    s.shown(1, preview=False)  # the old full frame (if it still finished) does not settle the new view
    assert not s.settled
    assert not s.changed(1.05).interrupt  # moving: nothing to interrupt
    assert s.full_due(1.3)
    s.full_requested()
    s.full_interrupted(s.version - 1)  # about an old version: ignored
    assert s.phase is RenderPhase.RESTING
    s.full_interrupted(s.version)  # abandoned without a change: rest again, re-request
    assert s.phase is RenderPhase.MOVING and s.full_due(1.4)


def test_a_failed_full_frame_settles_until_the_next_change():
    s = RenderStateMachine(rest_delay_s=0.0)
    s.changed(5.0)
    assert s.full_due(5.0)
    s.full_requested()
    s.full_failed(s.version - 1)
    assert not s.settled
    s.full_failed(s.version)
    assert s.settled and not s.full_due(9.0)
    s.changed(9.0)
    assert s.full_due(9.0)


def test_while_the_button_is_held_the_rest_takes_longer():
    s = RenderStateMachine(rest_delay_s=0.15, hold_delay_s=0.5)
    s.changed(0.0)
    assert s.full_due(0.2) and not s.full_due(0.2, holding=True)  # a pause between two bursts of moves
    assert s.full_due(0.5, holding=True)


def test_progressive_levels_half_then_full_and_a_change_interrupts_any_level():
    s = RenderStateMachine(rest_delay_s=0.0, levels=(0.5, 1.0))
    s.changed(0.0)
    assert s.full_due(0.0) and s.full_scale == 0.5 and s.full_level == (0, 2)
    s.full_requested()
    assert not s.shown(s.version, preview=True)  # a late preview: nothing due
    assert s.shown(s.version, preview=False, scale=0.5)  # the half-size level: the full one is due next
    assert s.phase is RenderPhase.RESTING and not s.settled and s.full_scale == 1.0 and s.full_level == (1, 2)
    s.full_requested()  # (already resting: stays)
    assert s.rendering_full
    c = s.changed(1.0)  # a drag during the full level
    assert c.interrupt and s.full_scale == 0.5  # the next rest starts from the half level again
    s.full_requested()
    assert s.shown(s.version, preview=False, scale=0.5)
    s.full_interrupted(s.version)  # abandoned without a change: the same (full) level is asked again
    assert s.phase is RenderPhase.MOVING and s.full_scale == 1.0
    s.full_requested()
    assert not s.shown(s.version, preview=False, scale=1.0)
    assert s.settled
    s.levels = (1.0,)  # a fast machine: one level from the next change on
    assert s.full_scale == 1.0
    s.changed(2.0)
    s.full_requested()
    assert not s.shown(s.version, preview=False) and s.settled


def test_refine_levels_and_bad_levels():
    assert refine_levels(None) == PROGRESSIVE_LEVELS == (0.5, 1.0)  # not measured yet: progressive
    assert refine_levels(2.0, 0.5) == (0.5, 1.0)
    assert refine_levels(0.3, 0.5) == (1.0,)
    assert refine_levels(float("nan")) == (0.5, 1.0)
    assert refine_levels(8.0, 0.5) == (0.25, 1.0)  # only the full frame known: ~ pixels; 8 s / 16 fits
    for bad in ((), (0.5,), (1.0, 0.5, 1.0), (0.0, 1.0), (0.5, 0.5, 1.0)):
        with pytest.raises(InputError):
            RenderStateMachine(levels=bad)


def test_first_level_fits_the_budget_from_measured_times():
    # full frame 2.0 s, a half-size level 0.8 s: 0.4 s fixed (every point rasterized) + 1.6 s * scale^2
    a, b = level_cost_model((1.0, 2.0), (0.5, 0.8))
    assert a == pytest.approx(0.4) and b == pytest.approx(1.6)
    assert refine_levels(2.0, 0.501, (0.5, 0.8)) == (0.25, 1.0)  # 0.4 + 1.6 / 16 = 0.5
    assert refine_levels(2.0, 0.49, (0.5, 0.8)) == (3 / 16, 1.0)  # 0.4 + 1.6 * 9 / 256 = 0.456
    assert refine_levels(2.0, 0.6, (0.5, 0.8)) == (5 / 16, 1.0)  # 6/16 would take 0.625 s
    assert refine_levels(2.0, 0.3, (0.5, 0.8)) == (0.125, 1.0)  # none fits: the smallest level
    assert refine_levels(0.9, 1.0, (0.5, 0.8)) == (1.0,)  # the full frame fits: one level
    assert refine_levels(1.2, 1.0, (0.25, 0.3)) == (0.5, 1.0)  # a cheap level: up to half size
    # unusable fits (a level slower than the full frame, equal scales): the pixel-count model
    assert level_cost_model((1.0, 1.0), (0.5, 2.0)) is None and level_cost_model((1.0, 1.0), (1.0, 0.5)) is None
    assert refine_levels(2.0, 0.5, (0.5, 3.0)) == (0.5, 1.0)
    assert refine_levels(2.0, 0.5, (0.5, float("inf"))) == (0.5, 1.0)


def test_retarget_changes_the_levels_of_a_full_frame_not_yet_requested():
    s = RenderStateMachine(rest_delay_s=0.15, levels=(0.5, 1.0))
    s.changed(1.0)
    s.retarget((1.0,))  # a release: a larger budget, one level
    assert s.full_scale == 1.0 and s.full_level == (0, 1)
    s.full_requested()
    s.retarget((0.25, 1.0))  # requested: nothing changes
    assert s.full_level == (0, 1)
    assert not s.shown(s.version, preview=False, scale=1.0) and s.settled
    assert s.levels == (0.5, 1.0)  # the next change takes the levels chosen for rests
    s.changed(2.0)
    assert s.full_scale == 0.5
    with pytest.raises(InputError):
        s.retarget((0.5,))
