"""``python -m radiosity_baker bake FILE.blend …`` (with the bpy module): see ``addon.cli``.

The command line is imported under the ``__main__`` guard alone: farm worker processes that
``multiprocessing`` spawns from this one import this module without it (and without bpy)."""
import sys

if __name__ == "__main__":
    from .addon.cli import main

    sys.exit(main(sys.argv[1:]))
