"""``python -m radiosity_baker bake FILE.blend …`` (with the bpy module): see ``addon.cli``."""
import sys

from .addon.cli import main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
