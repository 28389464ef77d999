"""Temporary changes to Blender data that are always put back."""
from __future__ import annotations

import contextlib


@contextlib.contextmanager
def temporarily(assignments):
    """Set ``(owner, attribute, value)`` triples for the duration of the block, then restore the
    old values in reverse order (also when the block raises)."""
    assignments = list(assignments)
    saved = [(owner, name, getattr(owner, name)) for owner, name, _ in assignments]
    try:
        for owner, name, value in assignments:
            setattr(owner, name, value)
        yield
    finally:
        for owner, name, value in reversed(saved):
            setattr(owner, name, value)
