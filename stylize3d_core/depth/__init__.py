"""Depth sources: every way a user can give a photo its depth (see DESIGN.md stage 1)."""
