"""The runtime, in wings that import only downhill (tests/test_layering.py checks it):

    base < mesh < kernels < assembly < solve < physics < contact < scene < model < change < run

Each wing is a package of modules; nothing is re-exported, so importing one module loads only
what it needs."""
WINGS = ("base", "mesh", "kernels", "assembly", "solve", "physics", "contact", "scene", "model", "change", "run")
