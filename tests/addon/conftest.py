"""Shared fixtures for tests that drive the real bpy module.

bpy can be imported once per process; it is imported here, after pointing Blender's user
resources at a temporary folder so tests never read or write the user's configuration.
Set RB_HARD_EXIT=1 to end the process with os._exit after the summary, an escape hatch for bpy
crashing while the interpreter shuts down (which would turn a green run into a failing exit code).
"""
import os
import tempfile

os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="rb-blender-user-")

import bpy  # noqa: E402  (must follow the environment variable)
import pytest  # noqa: E402

import radiosity_baker  # noqa: E402

if hasattr(radiosity_baker, "register"):
    radiosity_baker.register()


@pytest.fixture
def empty_scene():
    """A fresh empty file (factory settings); yields its scene."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    yield bpy.context.scene


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_sessionfinish(session, exitstatus):
    # Outermost wrapper: the code after ``yield`` runs once the terminal summary is printed.
    yield
    if os.environ.get("RB_HARD_EXIT") == "1":
        os._exit(int(session.exitstatus))
