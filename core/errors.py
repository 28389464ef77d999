"""Exceptions of the bake, shared by every stage."""


class BakeError(RuntimeError):
    """A bake that cannot run; the message says why and names the object where there is one."""


class BakeCancelled(RuntimeError):
    """The user cancelled the bake; nothing was written."""


class SettingsError(BakeError, ValueError):
    """A setting out of range; the message names it."""
