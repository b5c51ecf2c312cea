"""Image files: multi-layer EXR (:mod:`.exr`, through OpenEXR) and PNG (:mod:`.png`, through Pillow)."""
