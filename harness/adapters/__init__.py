"""Adapters: real renderers and their samplers, measured like the core's estimators.

A renderer adapter turns a scene and its settings into a ``Renderer`` (see ``base``): it
renders at a budget (samples or frames per pixel) and a seed and returns a float image and
its wall time.  Renderer modules are imported only when a suite or test uses them, so a
suite of core cases never imports Mitsuba or OpenGL.  ``command`` runs any renderer with a
command line, ``python`` a team's render function; third-party adapters register under the
entry-point group ``harness.adapters``.
"""
from harness.adapters.base import (
    ADAPTERS,
    ImageFaults,
    Render,
    Renderer,
    RenderError,
    adapter_names,
    image_faults,
    read_image,
    renderer,
)

__all__ = ["ADAPTERS", "ImageFaults", "Render", "Renderer", "RenderError", "adapter_names", "image_faults",
           "read_image", "renderer"]
