"""The names and tags by which the add-on knows what its bakes added to a file, so that a rebake
reuses it and clearing removes it and nothing of the user's."""

# Mesh custom property on a ``Lightmap`` UV map a bake created.
UV_TAG = "radiosity_baker_uv"
# Image custom property on a lightmap image a bake loaded (its value: the page name).
IMAGE_TAG = "radiosity_baker_lightmap"
# Material nodes a bake added are named with this prefix.
NODE_PREFIX = "RB Lightmap"
NODE_UV, NODE_IMAGE, NODE_MULTIPLY = (f"{NODE_PREFIX} UV", f"{NODE_PREFIX}", f"{NODE_PREFIX} Multiply")
# Object custom property naming the lightmap image (page) a bake put the object on.
OBJECT_TAG = "radiosity_baker_page"
# Image custom property on a lightmap image: the ``--directional`` layout of the file beside it.
DIRECTIONAL_TAG = "radiosity_baker_directional"
# Object, mesh and material custom property on the probes' viewport display (``addon.probes``).
PROBES_TAG = "radiosity_baker_probes"
