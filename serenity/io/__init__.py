"""Image files: multi-layer EXR (:mod:`.exr`, through OpenEXR), PNG (:mod:`.png`, through Pillow) and
pixel masks (:mod:`.mask`)."""
